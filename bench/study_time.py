"""Where a study's job time goes: the workflow's benchmark files summed per rule.

Every rule writes ``RESULTS/benchmarks/<rule>/...tsv`` (Snakemake's ``benchmark:``; column
``s`` is the job's wall time, Python start included). The share of the plot rules is the
issue's measure of whether plotting dominates a study.

Run after a study: python bench/study_time.py [RESULTS]   (default: results)
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict
from pathlib import Path

from timing import machine  # bench/timing.py

PLOT_RULES = ("plot_stage", "plot_pair", "plotly_js")


def job_seconds(results: Path, since: float = 0.0) -> dict[str, list[float]]:
    """``{rule: [wall seconds of each job]}`` from the benchmark files under ``results``
    (only those written after ``since``, in seconds since the epoch, when given)."""
    root = results / "benchmarks"
    if not root.is_dir():
        sys.exit(f"{root}: no benchmark files; run the study first (snakemake --cores 2)")
    by_rule: dict[str, list[float]] = defaultdict(list)
    for tsv in sorted(root.rglob("*.tsv")):
        if tsv.stat().st_mtime < since:
            continue
        rule = tsv.relative_to(root).parts[0].removesuffix(".tsv")
        with tsv.open() as f:
            rows = list(csv.DictReader(f, delimiter="\t"))
        by_rule[rule] += [float(r["s"]) for r in rows]
    return by_rule


def main() -> None:
    results = Path(sys.argv[1] if len(sys.argv) > 1 else "results")
    by_rule = job_seconds(results)
    total = sum(sum(t) for t in by_rule.values())
    print(machine())
    print(f"{results}: {sum(len(t) for t in by_rule.values())} jobs, {total:.1f} s of job time")
    print(f"{'rule':<12} {'jobs':>5} {'total s':>9} {'mean s':>8} {'share':>7}")
    for rule, times in sorted(by_rule.items(), key=lambda kv: -sum(kv[1])):
        print(
            f"{rule:<12} {len(times):>5} {sum(times):>9.1f} {sum(times) / len(times):>8.2f} {sum(times) / total:>7.1%}"
        )
    plot = sum(sum(by_rule.get(r, [])) for r in PLOT_RULES)
    print(f"plot jobs ({', '.join(PLOT_RULES)}): {plot:.1f} s, {plot / total:.1%} of job time")


if __name__ == "__main__":
    main()

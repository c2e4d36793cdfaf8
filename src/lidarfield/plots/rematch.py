"""Figures of rematching: per pair, the pose error of every trial stage by stage and method by
method; for the study, per hypothesis, the change in median error it brings to each method."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..analysis.rematch import ERRORS, read_rematch
from .output import save
from .pair_stats import column
from .settings import plot_settings
from .style import Margins, figure

# A trial where no estimate was made has a NaN error: drawn at the top of the axes, as an x.
_FLOOR = {"translation": 1e-5, "rotation": 1e-4}  # log axes: an error of 0 is drawn here (m, deg)
# A diverged estimate can be 1e11 m off: drawn at this ceiling (m, deg), as a triangle, so that
# the axes keep the scale of the estimates that mean something (starts are < 1 m, < 5 deg off).
_CEILING = {"translation": 10.0, "rotation": 90.0}


def pose_error_figure(stages: list[tuple[int, str, dict]], pair: str, dpi: int, reference: str = "reference"):
    """Translation and rotation error against stage, per method: every trial (dots), its
    median (line) and 10-90th percentile band. ``stages``: (level, hypothesis, table)."""
    stages = sorted(stages, key=lambda s: s[0])
    methods = list(dict.fromkeys(m for _, _, t in stages for m in t["method"].tolist()))
    fig = figure(8.0, 7.0, dpi, Margins(left=1.0, right=0.3, bottom=0.8, top=0.6, hspace=0.12))
    axes = fig.subplots(2, 1, sharex=True)
    levels = np.array([level for level, _, _ in stages], dtype=float)
    width = 0.6 / max(len(methods), 1)
    for ax, (error, (key, unit)) in zip(axes, ERRORS.items()):
        for i, method in enumerate(methods):
            x = levels + (i - (len(methods) - 1) / 2) * width
            values = [
                np.clip(t[key][t["method"] == method].astype(float), _FLOOR[error], _CEILING[error])
                for _, _, t in stages
            ]
            median = np.array([np.nanmedian(v) if np.isfinite(v).any() else np.nan for v in values])
            low = np.array([np.nanpercentile(v, 10) if np.isfinite(v).any() else np.nan for v in values])
            high = np.array([np.nanpercentile(v, 90) if np.isfinite(v).any() else np.nan for v in values])
            color = f"C{i}"
            ax.fill_between(x, low, high, color=color, alpha=0.15, lw=0)
            ax.plot(x, median, "o-", color=color, label=f"{method} (median, 10-90%)")
            for xk, v in zip(x, values):
                finite, diverged = np.isfinite(v), v >= _CEILING[error]
                ax.plot(np.full(finite.sum(), xk), v[finite], ".", color=color, alpha=0.5, ms=4)
                if diverged.any():
                    ax.plot([xk], [_CEILING[error]], "^", color=color, ms=7, mec="black", mew=0.5)
                if (~finite).any():
                    ax.plot([xk], [1], "x", color=color, transform=ax.get_xaxis_transform(), clip_on=False)
        _error_scale(ax, [np.clip(t[key].astype(float), None, _CEILING[error]) for _, _, t in stages], _FLOOR[error])
        ax.set_ylabel(f"{error} error ({unit})")
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
    axes[0].legend(fontsize=8, loc="best")
    axes[0].set_title(
        f"{pair} · pose error of rematching each stage, against the {reference}\n(dots: trials; "
        f"triangle: {_CEILING['translation']:g} m, {_CEILING['rotation']:g} deg or more, diverged; x: no estimate)",
        fontsize=9,
    )
    axes[1].set_xticks(levels, [f"{int(level):02d}\n{name}" for level, name, _ in stages], fontsize=8)
    axes[1].set_xlabel("stage")
    return fig


def _error_scale(ax, values: list[np.ndarray], floor: float) -> None:
    """Logarithmic when the errors span more than a factor of 20 (a biased stage next to clean
    ones), linear from 0 otherwise (log ticks over a narrow span are unreadable)."""
    finite = np.concatenate([np.asarray(v, dtype=float) for v in values])
    finite = np.maximum(finite[np.isfinite(finite)], floor)
    if len(finite) and finite.max() > 20 * finite.min():
        ax.set_yscale("log")
    else:
        ax.set_ylim(bottom=0)


def plot_pair_rematch(rematch_paths: list[str | Path], out_dir: str | Path, settings: dict | None = None) -> list[Path]:
    """``pose_error.png`` of one pair from its stages' ``rematch.parquet`` files."""
    s = plot_settings(settings)
    stages, references = [], set()
    for path in rematch_paths:
        table, meta = read_rematch(path)
        stages.append((int(meta.get("level") or 0), str(meta.get("hypothesis")), table))
        references.add(
            {"truth": "truth", "registration": "study's registration"}.get(meta.get("reference"), "reference")
        )
    pair = Path(rematch_paths[0]).parents[2].name if rematch_paths else ""
    reference = references.pop() if len(references) == 1 else "reference"
    return save(pose_error_figure(stages, pair, s.dpi, reference), Path(out_dir), "pose_error", s)


# --- the study ------------------------------------------------------------------------------


# A change in a method's median error smaller than this share of it is not called a change:
# trials that converge to the same estimate differ by rounding, and a verdict on that is noise.
RELATIVE_CHANGE = 0.10
# Nor is a change smaller than a millimetre, whatever its share: on clean simulated scans the
# errors are fractions of a millimetre, where +60% is 0.07 mm, far below any lidar's range noise.
ABSOLUTE_CHANGE_M = 0.001


def hypothesis_effects(rows: list[dict], methods: list[str]) -> list[dict]:
    """Per hypothesis (stage level k >= 1) and method, over pairs, the median change from stage
    k-1 to k of the median translation and rotation errors (and of the translation error
    relative to stage k-1's), and of the field's 95th percentile magnitude. ``verdict``: the
    matching is "better" or "worse" when the relative change passes ``RELATIVE_CHANGE`` and the
    translation change ``ABSOLUTE_CHANGE_M``; ``worse_matching`` flags a hypothesis that
    shrinks the field but makes matching worse."""
    by_pair: dict[str, dict[int, dict]] = {}
    for row in rows:
        by_pair.setdefault(str(row.get("pair")), {})[int(row.get("level") or 0)] = row
    levels = sorted({level for stages in by_pair.values() for level in stages if level > 0})
    effects = []
    for level in levels:
        pairs = [stages for stages in by_pair.values() if level in stages and level - 1 in stages]
        hypothesis = pairs[0][level].get("hypothesis") if pairs else ""
        after = lambda key: column([p[level] for p in pairs], key)  # noqa: E731
        before = lambda key: column([p[level - 1] for p in pairs], key)  # noqa: E731

        def median(values: np.ndarray) -> float:
            return float(np.nanmedian(values)) if np.isfinite(values).any() else float("nan")

        field_change = median(after("p95_magnitude") - before("p95_magnitude"))
        for method in methods:
            key = f"rematch_{method}_translation_median_m"
            with np.errstate(divide="ignore", invalid="ignore"):
                relative = median((after(key) - before(key)) / before(key))
            change = median(after(key) - before(key))
            if relative < -RELATIVE_CHANGE and change <= -ABSOLUTE_CHANGE_M:
                verdict = "better"
            elif relative > RELATIVE_CHANGE and change >= ABSOLUTE_CHANGE_M:
                verdict = "worse"
            else:
                verdict = "no clear change"
            effects.append(
                {
                    "level": level,
                    "hypothesis": hypothesis,
                    "method": method,
                    "pairs": len(pairs),
                    "field_p95_change_m": field_change,
                    "translation_change_m": change,
                    "translation_relative_change": relative,
                    "rotation_change_deg": median(
                        after(f"rematch_{method}_rotation_median_deg") - before(f"rematch_{method}_rotation_median_deg")
                    ),
                    "verdict": verdict,
                    "worse_matching": bool(field_change < 0 and verdict == "worse"),
                }
            )
    return effects


def study_rematch_figure(rows: list[dict], methods: list[str], dpi: int):
    """Per hypothesis, bars of the median change (over pairs) of each method's median
    translation (cm) and rotation (deg) errors; a hypothesis that shrinks the field but worsens
    a method's matching has that bar hatched and outlined in red. Symmetric log axes, linear
    within the smallest change that counts (grey band): changes of 10 cm and of 0.5 mm both show."""
    from matplotlib.patches import Patch

    effects = hypothesis_effects(rows, methods)
    levels = sorted({e["level"] for e in effects})
    fig = figure(8.0, 6.5, dpi, Margins(left=0.95, right=0.3, bottom=0.8, top=0.7, hspace=0.12))
    axes = fig.subplots(2, 1, sharex=True)
    width = 0.8 / max(len(methods), 1)
    floor_cm = ABSOLUTE_CHANGE_M * 100
    for ax, key, scale, label, linear in (
        (axes[0], "translation_change_m", 100, "Δ median translation error (cm)", floor_cm),
        (axes[1], "rotation_change_deg", 1, "Δ median rotation error (deg)", 0.01),
    ):
        ax.set_yscale("symlog", linthresh=linear, linscale=0.5)
        for i, method in enumerate(methods):
            mine = [e for e in effects if e["method"] == method]
            x = np.array([e["level"] for e in mine]) + (i - (len(methods) - 1) / 2) * width
            bars = ax.bar(x, [e[key] * scale for e in mine], width * 0.9, color=f"C{i}")
            for bar, e in zip(bars, mine):
                if e["worse_matching"]:
                    bar.set_hatch("//")
                    bar.set_edgecolor("red")
        ax.axhline(0, color="black", lw=0.6)
        ax.set_ylabel(label)
        ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    axes[0].axhspan(-floor_cm, floor_cm, color="0.85", zorder=0, lw=0)
    handles = [Patch(color=f"C{i}", label=m) for i, m in enumerate(methods)]
    handles.append(Patch(color="0.85", label=f"< {ABSOLUTE_CHANGE_M * 1000:g} mm: no clear change"))
    handles.append(
        Patch(
            facecolor="white",
            edgecolor="red",
            hatch="//",
            label=f"field shrinks, matching worse (> {RELATIVE_CHANGE:.0%})",
        )
    )
    fig.legend(
        handles=handles,
        loc="upper center",
        ncol=len(handles),
        fontsize=7,
        frameon=False,
        bbox_to_anchor=(0.5, 1 - 0.32 / 6.5),
    )
    fig.suptitle(
        "rematching: what each hypothesis does to the pose error (median over pairs; below 0: it helps)",
        fontsize=10,
        y=1 - 0.08 / 6.5,
        va="top",
    )
    names = {e["level"]: e["hypothesis"] for e in effects}
    axes[1].set_xticks(levels, [f"{level:02d}\n{names[level]}" for level in levels], fontsize=8)
    axes[1].set_xlabel("hypothesis (stage k against stage k-1)")
    return fig

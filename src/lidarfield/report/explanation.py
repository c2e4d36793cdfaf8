"""What ``lidarfield explain`` (and a study pair's explain target) writes, and the study
report's section on it.

An explanation's folder holds ``stack.yaml`` (the stack found, a ready config), ``steps.csv``
(one row per step, ``study.explain_loop.STEP_COLUMNS``), ``explain.json`` (the stack, the steps and
why the loop stopped: what the study report reads), ``figures/`` (per stage its field, or
before / after the step and what it removed) and ``explain.html`` (the page showing them step
by step). The study report's section lists per pair the stack found, and per hypothesis how
often the loop chose it.
"""

from __future__ import annotations

import csv
import functools
import io
import json
import logging
import multiprocessing
import queue
import shutil
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .. import __version__
from ..analysis.field_stats import summary_json_safe
from ..errors import InputError
from ..field.file import field_meta
from ..field.grid import FieldSettings
from ..io.atomic import write_text
from ..plots.pair_stats import pair_figure_png
from ..plots.settings import figure_settings
from ..plots.stage import draw_stage
from ..plots.stage_data import StageData, vector_field
from ..study.explain_loop import (
    STEP_COLUMNS,
    TABLE_COLUMNS,
    ExplainedStage,
    Explanation,
    format_step,
    stack_config,
)
from .page import esc, image, image_file, link, page, relative_href, table
from .pair_page import DPI, PAIR_FIGURES

log = logging.getLogger(__name__)

STACK_FILE, STEPS_FILE, RECORD_FILE, PAGE_FILE, FIGURES_DIR = (
    "stack.yaml",
    "steps.csv",
    "explain.json",
    "explain.html",
    "figures",
)
STAGE_CAPTIONS = {
    "field_top": "the field from above",
    "before_after": "before / after the step (same axes, same colour scale)",
    "removed_top": "what the step removed, from above",
}


def write_explanation(
    explanation: Explanation,
    settings: FieldSettings,
    grid_section: dict,
    out_dir: str | Path,
    plots: dict | None,
    figures: Callable[[], list[list[Path]]] | None = None,
) -> list[Path]:
    """Write an explanation's folder (see the module docstring); returns the files written.
    ``figures``: returns each stage's, drawn into it (``StageFigures.paths``), called once the
    page's pair figures are drawn (the last stage's may be drawn meanwhile by another process);
    None: drawn here."""
    out_dir = Path(out_dir)
    rows = explanation.summary_rows()
    pair_images = [pair_figure_png(stem, rows, DPI) for stem, _ in PAIR_FIGURES]
    if figures is None:
        drawn = draw_explanation(explanation, settings, fresh_figures_dir(out_dir), plots)
    else:
        drawn = figures()
    written = [out_dir / name for name in (STACK_FILE, STEPS_FILE, RECORD_FILE, PAGE_FILE)]
    stack = stack_config(explanation, grid_section)
    write_text(written[0], stack)
    write_text(written[1], steps_csv(explanation.steps))
    write_text(written[2], json.dumps(summary_json_safe(explanation.record()), indent=1, allow_nan=False) + "\n")
    write_text(written[3], explain_page(explanation, stack, pair_images, drawn, out_dir))
    return written + [path for paths in drawn for path in paths]


def fresh_figures_dir(out_dir: Path) -> Path:
    """The folder's ``figures/``, without an earlier explanation's steps."""
    shutil.rmtree(out_dir / FIGURES_DIR, ignore_errors=True)
    return out_dir / FIGURES_DIR


def steps_csv(steps: list[dict]) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=STEP_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(steps)
    return out.getvalue()


def stage_data(pair_name: str, explained: ExplainedStage, settings: FieldSettings) -> StageData:
    """An explained stage as the figures take a stage folder's contents."""
    stage = explained.stage
    field = vector_field(explained.columns, field_meta(settings, explained.statistics))  # its own edges
    meta = stage.metadata(explained.label)
    return StageData(Path(pair_name) / "explain" / explained.label, stage.pair, meta, stage.removed_columns(), field)


def draw_explanation(
    explanation: Explanation, settings: FieldSettings, figures_dir: Path, plots: dict | None
) -> list[list[Path]]:
    """Per stage its figures (``draw_explained_stage``)."""
    stages = explanation.stages
    return [
        draw_explained_stage(stages, k, explanation.pair_name, settings, figures_dir, plots) for k in range(len(stages))
    ]


def draw_explained_stage(
    stages: list[ExplainedStage],
    k: int,
    pair_name: str,
    settings: FieldSettings,
    figures_dir: Path,
    plots: dict | None,
) -> list[Path]:
    """Stage ``k``'s figures (``plots.stage.draw_stage``): stage 0's field from above; a step's
    before / after it on the same axes and, when it removed points, what it removed."""
    stage = stage_data(pair_name, stages[k], settings)
    names = ["field_top"] if k == 0 else ["before_after"] + (["removed_top"] if len(stage.removed["cloud"]) else [])
    chosen = {**figure_settings(plots), "figures": names, "interactive": False}
    previous = stage_data(pair_name, stages[k - 1], settings) if k else None
    return draw_stage(stage, previous, figures_dir / stages[k].label, chosen)


class StageFigures:
    """Each stage's figures drawn as soon as the loop has decided the stage (``explain_pair``'s
    ``on_stage``), into a fresh ``figures/`` of ``out_dir``; ``paths()``: what
    ``write_explanation`` takes. With ``background``, the stages are drawn one after the other
    by one drawing process while the loop ranks the next step's candidates (the figures are the
    same files: the same code on the same data); else here. That process is spawned, not
    forked: the caller has threads (the candidates' pool, Open3D's), and a fork copies their
    locks, which can deadlock the child (Python 3.12+ warns). It starts, and imports the
    drawing code, as the object is made: made before the scans are registered, that start-up
    runs meanwhile. Each stage goes to it pickled with the stage before it (what its before /
    after figure shows). A context manager: on leaving it, the drawing process is stopped."""

    def __init__(self, pair_name: str, settings: FieldSettings, out_dir: Path, plots: dict | None, background: bool):
        self.draw = functools.partial(
            draw_explained_stage,
            pair_name=pair_name,
            settings=settings,
            figures_dir=fresh_figures_dir(out_dir),
            plots=plots,
        )
        self.drawing = _DrawingProcess(self.draw) if background else None
        self.drawn: list = []  # per stage: its paths, or None while the drawing process has them

    def __call__(self, stages: list[ExplainedStage]) -> None:
        k = len(stages) - 1
        if self.drawing is None:
            self.drawn.append(self.draw(stages, k))
            return
        shown = stages[max(k - 1, 0) : k + 1]  # the stage and the one before it (stage 0: itself)
        self.drawing.jobs.put((shown, len(shown) - 1))
        self.drawn.append(None)

    def paths(self) -> list[list[Path]]:
        """Each stage's figures, once drawn; the drawing process's error raised here."""
        self.drawn = [self.drawing.result() if drawn is None else drawn for drawn in self.drawn]
        return self.drawn

    def __enter__(self) -> StageFigures:
        return self

    def __exit__(self, *exc) -> None:
        if self.drawing is not None:
            self.drawing.stop()


class _DrawingProcess:
    """A spawned process calling ``draw`` on each job put in ``jobs``; ``result``: the next
    job's result, or the error it raised raised here."""

    def __init__(self, draw: Callable):
        spawn = multiprocessing.get_context("spawn")
        self.jobs, self.results = spawn.Queue(), spawn.Queue()  # put() does not wait for the drawing
        self.process = spawn.Process(target=_draw_jobs, args=(draw, self.jobs, self.results), daemon=True)
        self.process.start()

    def result(self):
        while True:
            try:
                ok, value = self.results.get(timeout=1.0)
                break
            except queue.Empty:
                if not self.process.is_alive():  # killed (out of memory, a signal) before it could answer
                    raise RuntimeError(
                        f"the process drawing the figures ended with exit code {self.process.exitcode}"
                    ) from None
        if not ok:
            raise value
        return value

    def stop(self) -> None:
        self.jobs.cancel_join_thread()  # jobs it will not take: not flushed at exit
        self.process.terminate()
        self.process.join()


def _draw_jobs(draw: Callable, jobs, results) -> None:
    """In the drawing process: each job drawn, its result or the error it raised put in ``results``."""
    for args in iter(jobs.get, None):
        try:
            results.put((True, draw(*args)))
        except Exception as e:  # to the parent, which raises it
            results.put((False, e))


def explain_page(
    explanation: Explanation, stack: str, pair_images: list[bytes], figures: list[list[Path]], out_dir: Path
) -> str:
    """The page: the steps' table, the stack found, the pair figures stage by stage
    (``pair_images``, PNG, in ``PAIR_FIGURES``' order), and each step's figures."""
    name = explanation.pair_name
    body = [
        f"<h1>explain · {esc(name)}</h1>",
        f'<p class="note">lidarfield {esc(__version__)}. From the registered pair, the loop applied the best '
        "candidate of “what to try next” worth it (the config's <code>explain</code> settings), recomputed the "
        f"field and repeated. {len(explanation.steps)} step(s); stopped: {esc(explanation.stop)}; the field's verdict "
        f"at the end: <b>{esc(explanation.verdict)}</b>. Energy = Σ min(n1, n2)·|v|² over the valid voxels "
        "(m² × points); the whitened reduction, which ranks and stops the candidates, is that of Σ |C^-1/2 v|², "
        "each vector in units of its noise; both are over the voxels valid before and after the step.</p>",
        *(f'<p class="note">Finding: {esc(finding)}</p>' for finding in explanation.findings),
        "<h2>Steps</h2>",
        table(list(TABLE_COLUMNS), [[row[c] for c in TABLE_COLUMNS] for row in explanation.steps], text_columns=2)
        if explanation.steps
        else '<p class="note">No step: the field was not patterned, or no candidate was worth it.</p>',
        "<h2>The stack found</h2>",
        f'<p class="note">{esc(STACK_FILE)}, a ready config (<code>lidarfield run --config {esc(STACK_FILE)}</code>, '
        "or its <code>hypotheses:</code> in a study):</p>",
        f"<pre>{esc(stack)}</pre>",
        "<h2>Stage by stage</h2>",
        '<div class="figures">',
        *(image(png, f"{name}: {caption}") for png, (_, caption) in zip(pair_images, PAIR_FIGURES)),
        "</div>",
        "<h2>Each step</h2>",
    ]
    for k, (explained, paths) in enumerate(zip(explanation.stages, figures)):
        title = "the registered pair" if k == 0 else f"step {k}: {explained.stage.name}"
        body.append(f"<h3>{esc(title)}</h3>")
        if k:
            body.append(f"<p>{esc(format_step(explanation.steps[k - 1]))}</p>")
        body.append('<div class="figures">')
        body += [image_file(p, f"{explained.label}: {STAGE_CAPTIONS[p.stem]}") for p in paths if p.suffix == ".png"]
        body.append("</div>")
    return page(f"lidarfield explain: {name}", body)


def read_explanations(paths: list[str | Path]) -> list[dict]:
    """The ``explain.json`` records of a study's pairs, each with its ``path``."""
    records = []
    for path in paths:
        try:
            record = json.loads(Path(path).read_text())
        except (OSError, ValueError) as e:
            raise InputError(f"not a readable explain record ({e})", path) from None
        records.append({**record, "path": str(path)})
    return records


def stack_names(record: dict) -> list[str]:
    return [next(iter(step)) for step in record["stack"]]


def study_explain_parts(records: list[dict], out_dir: Path) -> list[str]:
    """The study report's section: per pair the stack found (linking its page), and per
    hypothesis how often the loop chose it. Nothing without records."""
    if not records:
        return []
    records = sorted(records, key=lambda r: r["pair"])
    pairs = [
        [
            link(relative_href(Path(r["path"]).parent / PAGE_FILE, out_dir), r["pair"]),
            " → ".join(stack_names(r)) or "(none)",
            len(r["stack"]),
            r["stop"],
            r["verdict"],
        ]
        for r in records
    ]
    chosen = Counter(name for r in records for name in set(stack_names(r)))
    positions = {name: [] for name in chosen}
    reductions = {name: [] for name in chosen}
    for r in records:
        for step in r["steps"]:
            positions[step["hypothesis"]].append(step["step"])
            reductions[step["hypothesis"]].append(step["energy_reduction"])
    counts = [
        [
            name,
            n,
            f"{100 * n / len(records):.0f}%",
            float(np.median(positions[name])),
            float(np.median(reductions[name])),
        ]
        for name, n in sorted(chosen.items(), key=lambda item: (-item[1], item[0]))
    ]
    ended = Counter(r["verdict"] for r in records)
    return [
        "<h2>What explain found</h2>",
        f'<p class="note">The stack the loop found on its own for each of {len(records)} pair(s) '
        "(<code>snakemake explain</code>; the config's <code>explain</code> settings); at the end the field was "
        + ", ".join(f"{esc(v)} for {n}" for v, n in sorted(ended.items()))
        + ".</p>",
        table(["pair", "stack found", "steps", "stopped", "verdict at the end"], pairs, text_columns=2),
        table(
            ["hypothesis", "pairs that chose it", "share of the pairs", "median step", "median energy reduction"],
            counts,
            text_columns=1,
        ),
    ]

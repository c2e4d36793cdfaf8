"""Drawing a few figures once in a process that later forks the plot jobs.

The first figure a process draws pays for what matplotlib and plotly set up on first use:
fonts found and loaded, glyph and text-layout caches, plotly's lazily imported figure classes.
That was a sixth of a stage's figures when each job paid it again. The job worker draws a few
of a small synthetic pair's figures once, in steps short enough to run between jobs, and every
job it forks afterwards finds all of it ready.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from pathlib import Path

from . import plot_stage
from .synthetic import write_synthetic_pair

WARM_UP_FIGURES = ("field_top", "field_perspective")


def warm_up_steps() -> Iterator[str]:
    """Draw a synthetic stage's figures into a temporary folder, one per step, and yield the
    name of each. One 2-D figure, one 3-D figure and the plotly view set up what all of a
    stage's figures use: drawing the other three too made a stage's figures no faster. The
    folder is gone when the iterator ends or is closed."""
    with tempfile.TemporaryDirectory(prefix="lidarfield-warm-up-") as folder:
        stages = write_synthetic_pair(Path(folder) / "pair", "pair", levels=2, n=3000)
        yield "synthetic pair"
        out = Path(folder) / "figures"
        for name in WARM_UP_FIGURES:
            plot_stage(stages[1], stages[0], out, {"figures": [name], "interactive": False})
            yield name
        plot_stage(stages[1], None, out, {"figures": [], "interactive": True}, plotly_js=out / "plotly.min.js")
        yield "field_3d"

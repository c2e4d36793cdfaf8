"""Drawing a few figures once in a process that later forks the plot jobs.

The first figure a process draws pays for what matplotlib and plotly set up on first use:
fonts found and loaded, glyph and text-layout caches, plotly's lazily imported figure classes.
That was a sixth of a stage's figures when each job paid it again. The job worker draws a few
figures of a small simulated pair once, in steps short enough to run between jobs, and every
job it forks afterwards finds all of it ready. The pair goes through the workflow's own jobs
(simulate, register, mitigate, field), so the figures are drawn from the files a study writes.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from pathlib import Path

from ..commands.jobs import stack_jobs
from ..pair import write_pair
from ..plots import plot_stage
from ..poses import pose_from_xyzrpy
from ..registration import register_pair
from ..sensors.models import sensor_model
from ..simulation.raycast import simulate_scan
from ..simulation.scene import load_scene

WARM_UP_FIGURES = ("field_top", "field_perspective")
# The default study's simulated pair, with the 16-beam VLP-16: about 20,000 points a scan.
SCENE, SENSOR = "paper-intersection", "vlp16"
POSES = ([0, 0, 3, 0, 0, 0], [1, 1, 3, 0, 0, 0.05])
STACK = ({"field_of_view": {}},)


def write_warm_up_stages(folder: Path) -> list[Path]:
    """Stages 0 and 1 (``field_of_view``) of the simulated pair, written by the workflow's jobs
    into ``folder``; returns the stage folders."""
    scene, sensor = load_scene(SCENE), sensor_model(SENSOR)
    scans = [simulate_scan(scene, sensor, pose_from_xyzrpy(pose)) for pose in POSES]
    registered = folder / "registered.parquet"
    write_pair(registered, register_pair(*scans, "truth"))
    stages = [folder / "stages" / f"{level:02d}-warm-up" for level in range(len(STACK) + 1)]
    stack_jobs(registered, list(STACK), stages, {}, "warm-up")
    return stages


def warm_up_steps() -> Iterator[str]:
    """Draw a simulated stage's figures into a temporary folder, one per step, and yield the
    name of each. One 2-D figure, one 3-D figure and the plotly view set up what all of a
    stage's figures use: drawing the other three too made a stage's figures no faster. The
    folder is gone when the iterator ends or is closed."""
    with tempfile.TemporaryDirectory(prefix="lidarfield-warm-up-") as folder:
        stages = write_warm_up_stages(Path(folder) / "pair")
        yield "simulated pair"
        out = Path(folder) / "figures"
        for name in WARM_UP_FIGURES:
            plot_stage(stages[1], stages[0], out, {"figures": [name], "interactive": False})
            yield name
        plot_stage(stages[1], None, out, {"figures": [], "interactive": True}, plotly_js=out / "plotly.min.js")
        yield "field_3d"

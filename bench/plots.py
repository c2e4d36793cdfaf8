"""Time of the figures of one stage, and of a page embedding them, against the time of
computing its field (same data, same run).

Run: python bench/plots.py [n_points_per_cloud]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from lidarfield.field.kernel import discrepancy_field
from lidarfield.plots import plot_stage
from lidarfield.plots.png import compact_png
from lidarfield.plots.stage_data import load_stage
from timing import best_time, machine  # bench/timing.py

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the tests' synthetic study
from helpers.synthetic_study import SETTINGS, write_synthetic_pair  # noqa: E402


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 120_000
    print(machine())
    with tempfile.TemporaryDirectory() as tmp:
        dirs = write_synthetic_pair(Path(tmp) / "pair", "pair", levels=2, n=n)
        stage = load_stage(dirs[1])
        field_s, _ = best_time(lambda: discrepancy_field(stage.pair.xyz1, stage.pair.xyz2, SETTINGS))
        for label, settings in (
            ("png only, no 3-D view", {"interactive": False}),
            ("png + field_3d.html (default)", {}),
        ):
            plot_s, written = best_time(lambda: plot_stage(dirs[1], dirs[0], Path(tmp) / "figures", settings), repeat=2)
            print(
                f"{n} points per cloud, {label}: plot_stage {plot_s:.2f} s; field {field_s * 1000:.1f} ms; ratio "
                f"{plot_s / field_s:.0f}x"
            )
        pngs = [path.read_bytes() for path in written if path.suffix == ".png"]
        embed_s, _ = best_time(lambda: [compact_png(png) for png in pngs])
        print(
            f"a page embedding its {len(pngs)} figures (compact_png): {embed_s * 1000:.0f} ms, "
            f"{sum(map(len, pngs)) / 1e3:.0f} kB of PNG; "
            f"ratio {embed_s / field_s:.1f}x the field"
        )


if __name__ == "__main__":
    main()

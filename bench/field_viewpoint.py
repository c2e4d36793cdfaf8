"""Benchmark: what the change of viewpoint costs the field of a pair, against the field without it.

The pair: bench/explain.py's (the built-in scene paper-intersection-ego-car seen by the
80-channel sensor of the method's simulated pair, sensor 2 1 m further and 0.5 s later, each
cloud subsampled to 60,000 points), registered by the truth, on its grid.

Timed, best of R, in the same run: the field as it was computed before the viewpoint term (the
kernel with both scan patterns, ``field_from_voxel_ids``), the shared points
(``free_space.shared_points``: both range images and the co-visibility tests), the kernel with the
viewpoint term (its second pass of sums over the shared points), and the whole ``analyse_field``
(field, tags, statistics and randomness tests) as the field job runs it now.

Run: ``python bench/field_viewpoint.py [--points N] [--repeat R]``.
"""

from __future__ import annotations

import argparse

from explain import GRID, ego_car_pair  # bench/explain.py
from lidarfield.analysis.field_stats import analyse_field
from lidarfield.field.free_space import shared_points
from lidarfield.field.grid import field_settings_from_config
from lidarfield.field.kernel import field_from_voxel_ids
from lidarfield.field.pair_field import scan_patterns
from lidarfield.field.significance import Viewpoint
from timing import best_time, machine  # bench/timing.py


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=60_000, help="points per cloud")
    parser.add_argument("--repeat", type=int, default=5, help="best of this many runs")
    args = parser.parse_args()
    pair = ego_car_pair(args.points)
    settings = field_settings_from_config(GRID)
    ids1, ids2 = settings.grid.assign(pair.xyz1), settings.grid.assign(pair.xyz2)
    patterns = scan_patterns(pair)
    shared = shared_points(pair)
    viewpoint = Viewpoint(pair.origin2, *shared)
    print(machine())
    print(f"{len(pair.xyz1):,} + {len(pair.xyz2):,} points; shared {shared[0].mean():.1%} / {shared[1].mean():.1%}")
    before, _ = best_time(
        lambda: field_from_voxel_ids(ids1, pair.xyz1, ids2, pair.xyz2, settings, patterns=patterns), args.repeat
    )
    sharing, _ = best_time(lambda: shared_points(pair), args.repeat)
    after, _ = best_time(
        lambda: field_from_voxel_ids(
            ids1, pair.xyz1, ids2, pair.xyz2, settings, patterns=patterns, viewpoint=viewpoint
        ),
        args.repeat,
    )
    whole, _ = best_time(lambda: analyse_field(pair, settings), args.repeat)
    print(f"field kernel, no viewpoint term (before): {before * 1e3:7.1f} ms")
    print(f"shared points (range images, tests):      {sharing * 1e3:7.1f} ms")
    print(f"field kernel with the viewpoint term:     {after * 1e3:7.1f} ms")
    now = sharing + after
    print(f"the field before {before * 1e3:.1f} ms, now {now * 1e3:.1f} ms: {now / before:.2f}x")
    print(f"analyse_field now: {whole * 1e3:.1f} ms, of which the term {(sharing + after - before) / whole:.0%}")


if __name__ == "__main__":
    main()

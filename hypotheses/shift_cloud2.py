"""Example plugin hypothesis that corrects rather than removes: shift cloud 2 by a fixed vector.

Use it from a study config with

    hypotheses:
      - plugin: {file: hypotheses/shift_cloud2.py, function: shift, params: {shift_m: [-0.3, 0, 0]}}

A correcting hypothesis returns a mapping instead of ``(keep1, keep2)``:

- ``keep1``, ``keep2``: boolean keep-masks, as a removing hypothesis returns them (optional:
  every point kept);
- ``xyz1``, ``xyz2``: the corrected coordinates of **every** point of the cloud it was given,
  (N, 3) in frame 1, row for row (optional: the cloud is not moved). The stage keeps the rows
  of its keep-mask; the points it removes are recorded as they were, uncorrected;
- ``T_1_2``: sensor 2's corrected 4x4 pose in frame 1 (optional: unchanged), so later stages
  and the figures see the sensor where the correction puts it;
- ``fitted``: a JSON-able mapping of what was fitted and applied (finite numbers), written to
  the stage's summary row as its ``correction``.

A wrong shape, a value that is not finite or a ``fitted`` that is not JSON is one error naming
this file. Here nothing is fitted: the shift is the parameter, recorded as applied.
"""

from __future__ import annotations

import numpy as np


def shift(pair, params: dict) -> dict:
    """Cloud 2 and sensor 2 moved by ``shift_m`` (x, y, z in frame 1, metres); nothing removed."""
    offset = np.asarray(params.get("shift_m", [0.0, 0.0, 0.0]), dtype=float).reshape(3)
    T_1_2 = pair.T_1_2.copy()
    T_1_2[:3, 3] += offset
    return {
        "keep1": np.ones(len(pair.xyz1), dtype=bool),
        "keep2": np.ones(len(pair.xyz2), dtype=bool),
        "xyz2": pair.xyz2 + offset,
        "T_1_2": T_1_2,
        "fitted": {"shift_m": offset.tolist()},
    }

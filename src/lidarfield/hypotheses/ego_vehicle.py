"""``ego_vehicle``: remove the points on the vehicle that carries each sensor.

A point is removed when its range from its *own* sensor's origin is below ``radius_m`` (cloud 1
about sensor 1's origin, cloud 2 about sensor 2's origin, the translation of ``T_1_2``), or,
when ``box_m`` is given, when it lies inside that box expressed in its own sensor's frame.
Source paper: 3 m for a van in its text; the authors' script used 4.1 m.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..field.free_space import ranges
from ..pair import RegisteredPair
from .geometry import check_box, inside_box, own_frame_points
from .params import doc

Box = tuple[float, float, float, float, float, float]


@dataclass(frozen=True)
class Params:
    radius_m: float | None = field(
        default=3.0, metadata=doc("remove points nearer than this to their own sensor (null: no radius test)")
    )
    box_m: Box | None = field(
        default=None,
        metadata=doc(
            "vehicle footprint [xmin, xmax, ymin, ymax, zmin, zmax] in each sensor's frame (points inside removed)"
        ),
    )

    def __post_init__(self):
        if self.radius_m is not None and not self.radius_m >= 0:
            raise ValueError(f"radius_m must be >= 0, got {self.radius_m}")
        check_box(self.box_m)


def ego_vehicle(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Keep-masks: False for the points within ``radius_m`` of (or in ``box_m`` about) their own sensor."""
    masks = []
    for xyz in own_frame_points(pair):
        on_vehicle = np.zeros(len(xyz), dtype=bool)
        if params.radius_m is not None:
            on_vehicle |= ranges(xyz) < params.radius_m
        if params.box_m is not None:
            on_vehicle |= inside_box(xyz, params.box_m)
        masks.append(~on_vehicle)
    return masks[0], masks[1]

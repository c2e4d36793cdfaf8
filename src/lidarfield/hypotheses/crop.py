"""``crop``: keep only the points inside range limits and a box.

Ranges are measured from each cloud's own sensor (as ``ego_vehicle`` does); the box is in frame
1, the frame both clouds share, so that both are cropped to the same region of the scene.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..field.free_space import ranges
from ..pair import RegisteredPair
from .ego_vehicle import Box
from .geometry import check_box, inside_box, own_frame_points
from .params import doc


@dataclass(frozen=True)
class Params:
    min_range_m: float = field(default=0.0, metadata=doc("remove points nearer than this to their own sensor"))
    max_range_m: float | None = field(
        default=None, metadata=doc("remove points farther than this from their own sensor (null: no limit)")
    )
    box_m: Box | None = field(
        default=None,
        metadata=doc("keep only points inside [xmin, xmax, ymin, ymax, zmin, zmax] in frame 1 (null: no box)"),
    )

    def __post_init__(self):
        if self.min_range_m < 0 or (self.max_range_m is not None and self.max_range_m < self.min_range_m):
            raise ValueError(f"need 0 <= min_range_m <= max_range_m, got {self.min_range_m} and {self.max_range_m}")
        check_box(self.box_m)


def crop(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Keep-masks: inside ``[min_range_m, max_range_m]`` of the own sensor and inside ``box_m``."""
    masks = []
    for own, xyz in zip(own_frame_points(pair), (pair.xyz1, pair.xyz2)):
        r = ranges(own)
        keep = r >= params.min_range_m
        if params.max_range_m is not None:
            keep &= r <= params.max_range_m
        if params.box_m is not None:
            keep &= inside_box(xyz, params.box_m)
        masks.append(keep)
    return masks[0], masks[1]

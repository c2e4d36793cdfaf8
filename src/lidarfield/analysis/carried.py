"""What the vehicle carries: points that stay put in both sensors' own frames while the sensors
moved apart.

Between two scans of a drive the sensor moves, and with it the vehicle's own body (a car's roof
under the sensor, a truck's cargo body behind it, a roof rack's pole): the body keeps its
coordinates in each sensor's own frame, which nothing fixed in the world does. A point of one
cloud is *carried* when, each cloud taken in its own sensor's frame, the other cloud has a point
within ``OWN_M`` of it (the same rays met the same body), while in frame 1 (the world) the other
cloud has none within ``STATIC_M`` (a fixed surface there would have given the other scan a
return where this one is). A point passes both only if the motion between the sensors moved it
by more than ``STATIC_M - OWN_M`` (5 cm: five times the zoo's simulated range noise, about two
of a real lidar's, whose difference of two ranges has about 3 cm): from one place (the sensors
within that of each other, as registered) nothing is carried, whatever the scans hold.

A fixed plane that the motion maps onto itself (the ground or a ceiling under a drive on flat
ground, a wall along it) is sampled by the same rays at the same places in both sensors' frames
too, and in frame 1 its rings are shifted by the move, so part of it passes: of the points
within 3 m of the sensor on the real HDL-32E pair (0.49 m apart, indoors: a room's floor and
ceiling) 25% are carried; of a roof rack's pole or a truck's cargo body on the zoo's drives
95-100%, of the real ExpD van's body 97% (a car's roof under the sensor, itself such a plane but
for its edges, 12-96%). So what ``ego_vehicle`` removes is the vehicle when at least
``MIN_CARRIED_SHARE`` of it is carried (and ``MIN_CARRIED_POINTS``). A pair from one place
registered more than 5 cm off looks carried wherever its scans agree in their own frames.
Measured in docs/diagnosis.md ("The own body named from the points it carries").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..hypotheses.geometry import cloud_tree, near_in_own_frames
from ..pair import RegisteredPair

OWN_M = 0.05  # within this in both sensors' own frames: the same point of the body
STATIC_M = 0.10  # ... and no point of the other cloud within this in frame 1: not fixed in the world
MIN_CARRIED_SHARE = 0.5  # what ego_vehicle removes is the vehicle when this share of it is carried
MIN_CARRIED_POINTS = 50  # ... and at least this many points (a roof rack's pole gives hundreds)


def carried_points(pair: RegisteredPair, candidates: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Per cloud, which of its ``candidates`` (masks) are carried: the other cloud has a point
    within ``OWN_M`` of it in their own sensors' frames and none within ``STATIC_M`` in frame 1."""
    world = (pair.xyz1, pair.xyz2)
    carried = near_in_own_frames(pair, candidates, OWN_M)
    for k in (0, 1):
        if carried[k].any():
            near_world, _ = cloud_tree(pair, 2 - k).query(world[k][carried[k]], distance_upper_bound=STATIC_M)
            carried[k][carried[k]] = ~np.isfinite(near_world)
    return carried


@dataclass(frozen=True)
class CarriedBody:
    """Of the ``removed`` points a removal takes (both clouds), ``carried`` stay put in both
    sensors' frames (:func:`carried_points`)."""

    removed: int
    carried: int

    @property
    def is_vehicle(self) -> bool:
        return self.carried >= MIN_CARRIED_POINTS and self.carried >= MIN_CARRIED_SHARE * self.removed

    def statement(self) -> str:
        return (
            f"{self.carried} of the {self.removed} points ego_vehicle removes stay put in both sensors' frames while "
            "the sensors moved: the vehicle's own body"
        )


def carried_body(pair: RegisteredPair, keep1: np.ndarray, keep2: np.ndarray) -> CarriedBody:
    """How much of a removal (keep-masks) is carried by the vehicle."""
    carried = carried_points(pair, (~keep1, ~keep2))
    removed = int(np.count_nonzero(~keep1) + np.count_nonzero(~keep2))
    return CarriedBody(removed, int(np.count_nonzero(carried[0]) + np.count_nonzero(carried[1])))

"""``realign`` against the tool's registrations on real pairs started 0.3 m and 0.5 deg off their
reference pose (``tests/helpers/real_pairs.py``; the full table: ``bench/realign_real.py``,
docs/hypotheses.md)."""

from __future__ import annotations

import pytest

from helpers.real_pairs import OFFSETS, point_distance_cm, real_pair, realigned, registered

# Measured on 2026-11-27 from the "+x, yaw" start (cm from the reference, median point distance):
# hdl32: GICP 1.40, NDT 3.97, point-to-plane ICP 2.42, realign 2.05; os1 0->1: 2.22, 2.29, 2.05
# and 1.97. The tolerance, 1 cm, is under half the distance between the HDL-32E pair's two
# published references (2.2 cm): what a reference is worth. (Not ExpD: there realign lands 9.00,
# beyond NDT's 8.76; docs/hypotheses.md says why.)
TOLERANCE_CM = 1.0
SPREAD = ("gicp", "ndt", "icp_point_to_plane")


@pytest.mark.parametrize("name", ["hdl32", "os1 0->1"])
def test_realign_lands_no_worse_than_the_best_registration(shared_data, name):
    real = real_pair(shared_data, name)
    start = OFFSETS["+x, yaw"] @ real.reference
    distance = {m: point_distance_cm(registered(real, m, start), real.reference, real.scan2.xyz) for m in SPREAD}
    own = point_distance_cm(realigned(real, start), real.reference, real.scan2.xyz)
    assert own <= min(distance.values()) + TOLERANCE_CM, (own, distance)

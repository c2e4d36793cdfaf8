"""``realign`` against the tool's registrations on real pairs started 0.3 m and 0.5 deg off their
reference pose (``tests/helpers/real_pairs.py``; the full table: ``bench/realign_real.py``,
docs/hypotheses.md)."""

from __future__ import annotations

import pytest

from helpers.real_pairs import OFFSETS, point_distance_cm, real_pair, realigned, registered, shared_pair

# Measured on 2026-11-27 from the "+x, yaw" start (cm from the reference, median point distance),
# GICP, NDT, point-to-plane ICP and realign: hdl32 1.40, 3.97, 2.42 and 2.05; os1 0->1 2.22, 2.29,
# 2.05 and 1.97. ExpD, whose sensors stood 3 m apart and saw half their points alone: on all
# points 2.97, 8.76, 3.70 (realign 9.00); on the points both sensors saw, as realign's refit
# takes them, 8.44, 9.14 and 9.18. The tolerance, 1 cm, is under half the distance between the
# HDL-32E pair's two published references (2.2 cm): what a reference is worth.
# ICP's landing is held here (field_refinement off); the field's refinement that follows it by
# default moves the HDL-32E and OS1 landings 2.8 and 2.5 cm further (3.55 and 3.42 cm from the
# reference; 2026-11-27): to where the field's surfaces agree (on the OS1-128 frames their
# field then reads random, test_significance.py); which is nearer the truth the references
# cannot say. It must stay a refinement: under 4 cm from ICP's landing.
# Where two references are published (the HDL-32E pair), a landing's distance is their mean:
# T_target_source.txt is a GICP's and favours GICP. Since the registration's voxel is capped at
# 1 deg at the median range (2026-11-28, 0.066 m on this indoor pair), the tool's GICP lands
# 0.49 cm from it and 2.09 cm from relative.txt; realign 2.05 and 1.61 cm, NDT 1.90 and 1.70,
# point-to-plane ICP 2.20 and 2.22.
TOLERANCE_CM = 1.0
REFINEMENT_MAX_CM = 4.0
SPREAD = ("gicp", "ndt", "icp_point_to_plane")


@pytest.mark.parametrize("name, shared", [("hdl32", False), ("os1 0->1", False), ("expd", True)])
def test_realign_lands_no_worse_than_the_best_registration(shared_data, name, shared):
    real = real_pair(shared_data, name)
    start = OFFSETS["+x, yaw"] @ real.reference
    landed = realigned(real, start, {"field_refinement": False})
    matched = shared_pair(real, landed) if shared else real
    references = [T for T in (real.reference, real.other_reference) if T is not None]

    def from_references(T):
        return sum(point_distance_cm(T, reference, real.scan2.xyz) for reference in references) / len(references)

    distance = {m: from_references(registered(matched, m, start)) for m in SPREAD}
    own = from_references(landed)
    assert own <= min(distance.values()) + TOLERANCE_CM, (own, distance)
    refined = realigned(real, start)
    assert point_distance_cm(refined, landed, real.scan2.xyz) < REFINEMENT_MAX_CM

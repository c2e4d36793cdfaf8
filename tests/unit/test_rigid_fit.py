"""The field's rigid part fitted point-to-plane (``field.rigid_fit``) on real geometry: the
simulated intersection of the source paper, a corridor, and the real ExpD VLP-16 pair.

Two independent samplings (2 cm range noise) of the intersection, scan 2 registered wrong by
a known motion: a voxel mean sees only the normal part of a motion, so a point-to-point fit on
voxel means (what the statistics used before) found -0.13 m of a 0.3 m shift and called 98%
of the field's energy ``radial``.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from lidarfield.analysis.field_stats import field_statistics
from lidarfield.analysis.tags import voxel_tags
from lidarfield.field.grid import FieldSettings, SphericalGrid
from lidarfield.field.kernel import discrepancy_field
from lidarfield.field.rigid_fit import point_to_plane_fit
from lidarfield.io import read_scan
from lidarfield.io.pose_files import read_pose
from lidarfield.pair import RegisteredPair
from lidarfield.poses import apply_pose, pose_from_xyzrpy
from lidarfield.sensors.models import PRESETS

SETTINGS = FieldSettings(SphericalGrid())  # 36 x 10 deg, 5 x 8 deg from -20 to +20


@lru_cache(maxsize=1)
def intersection_scans() -> tuple[np.ndarray, np.ndarray]:
    """Two independent samplings (seeds 1, 2; 2 cm range noise) of the paper's intersection
    from the same pose, in the sensor frame."""
    from lidarfield import load_scene
    from lidarfield.simulation.raycast import simulate_scan

    scene, sensor = load_scene("paper-intersection"), PRESETS["paper-sim-80"]
    pose = pose_from_xyzrpy([0.0, 0.0, 3.0, 0.0, 0.0, 0.0])
    return tuple(simulate_scan(scene, sensor, pose, seed=s, range_noise_m=0.02).xyz for s in (1, 2))


def analysed(xyz1: np.ndarray, xyz2: np.ndarray, sensor: str = "paper-sim-80") -> tuple[dict, dict]:
    field = discrepancy_field(xyz1, xyz2, SETTINGS)
    pair = RegisteredPair(xyz1, xyz2, sensor1=PRESETS[sensor], sensor2=PRESETS[sensor])
    field.update(voxel_tags(field, pair, SETTINGS))
    return field, field_statistics(field, SETTINGS)


def test_a_shift_of_the_intersection_is_rigid_and_recovered():
    xyz1, xyz2 = intersection_scans()
    field, stats = analysed(xyz1, xyz2 + [0.3, 0.0, 0.0])
    np.testing.assert_allclose(stats["rigid_translation_m"], [-0.3, 0.0, 0.0], atol=0.01)
    assert stats["rigid_rotation_deg"] < 0.02
    assert stats["rigid_unconstrained"] == []
    assert stats["energy_share_rigid"] > 0.5 and stats["energy_share_radial"] < 0.4
    assert stats["rigid_energy_share"] > 0.6
    information = np.reshape(stats["rigid_information"], (6, 6))
    np.testing.assert_allclose(information, information.T, rtol=1e-12, atol=1e-9)
    assert np.linalg.eigvalsh(information).min() > 0


def test_a_yaw_of_the_intersection_is_recovered():
    xyz1, xyz2 = intersection_scans()
    _, stats = analysed(xyz1, apply_pose(pose_from_xyzrpy([0, 0, 0, 0, 0, math.radians(0.5)]), xyz2))
    assert abs(stats["rigid_rotation_deg"] - 0.5) < 0.02
    assert np.linalg.norm(stats["rigid_translation_m"]) < 0.01


def test_a_range_scale_and_offset_is_radial_not_rigid():
    xyz1, xyz2 = intersection_scans()
    r = np.linalg.norm(xyz2, axis=1, keepdims=True)
    _, stats = analysed(xyz1, xyz2 * 1.003 + 0.03 * xyz2 / r)  # scale 1.003 and +3 cm about sensor 2
    assert stats["energy_share_radial"] > 0.6 and stats["energy_share_rigid"] < 0.3
    assert stats["rigid_energy_share"] < 0.4


def test_independent_samplings_stay_near_zero():
    xyz1, xyz2 = intersection_scans()
    _, stats = analysed(xyz1, xyz2)
    assert np.linalg.norm(stats["rigid_translation_m"]) < 0.003 and stats["rigid_rotation_deg"] < 0.01
    assert stats["energy_share_rigid"] < 0.05


def test_the_normal_part_fit_recovers_a_small_motion_as_precisely_as_the_verdict_reads_it():
    """The generalised least squares of the surfaces' normal parts (weights 1 / se_normal^2,
    ``field_normal_part_fit``): on the intersection (two samplings, each cloud's scan pattern in
    the vectors' covariance) moved by 5 mm and turned 0.05 deg about z, it finds the motion to
    within 0.5 mm and 0.003 deg (measured 0.22 mm and 0.0018 deg), and the field corrected by it
    reads random (patterned before)."""
    from lidarfield.analysis.field_stats import analyse_field
    from lidarfield.field.rigid_fit import field_normal_part_fit

    xyz1, xyz2 = intersection_scans()
    sensor = PRESETS["paper-sim-80"]
    motion = pose_from_xyzrpy([0.004, 0.003, 0.0, 0.0, 0.0, math.radians(0.05)])
    moved = RegisteredPair(xyz1, apply_pose(motion, xyz2), sensor1=sensor, sensor2=sensor)
    columns, stats = analyse_field(moved, SETTINGS)
    assert stats["verdict"] == "patterned"
    surfaces = np.isfinite(columns["se_normal"])
    assert surfaces.sum() > 50 and np.all(columns["se_normal"][surfaces] > 0)
    fit = field_normal_part_fit(columns)
    correction = np.eye(4)
    correction[:3, :3], correction[:3, 3] = fit.rotation, fit.translation
    residual = correction @ motion  # the identity if the fit undid the motion
    assert np.degrees(math.acos(min(1.0, (np.trace(residual[:3, :3]) - 1) / 2))) < 0.003
    assert np.abs(residual[:3, 3]).max() < 0.0005
    corrected = RegisteredPair(xyz1, apply_pose(residual, xyz2), sensor1=sensor, sensor2=sensor)
    assert analyse_field(corrected, SETTINGS)[1]["verdict"] == "random"


def corridor(n: int, seed: int) -> np.ndarray:
    """Rays uniform over the grid's angles onto two walls at y = +-4 m and the ground 3 m below
    the sensor, open along x (to 60 m), with 2 cm of range noise."""
    rng = np.random.default_rng(seed)
    az, el = rng.uniform(-np.pi, np.pi, n), np.radians(rng.uniform(-20.0, 20.0, n))
    sight = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    with np.errstate(divide="ignore"):
        wall = np.where(sight[:, 1] != 0, 4.0 / np.abs(sight[:, 1]), np.inf)
        ground = np.where(sight[:, 2] < 0, -3.0 / sight[:, 2], np.inf)
    r = np.minimum(wall, ground)
    keep = r < 60.0
    return sight[keep] * (r[keep] + rng.normal(scale=0.02, size=keep.sum()))[:, None]


def test_a_corridor_does_not_constrain_its_axis():
    xyz1, xyz2 = corridor(60_000, 1), corridor(60_000, 2)
    _, stats = analysed(xyz1, xyz2 + [0.0, 0.1, 0.0])
    assert stats["rigid_unconstrained"] == ["translation x"]
    assert abs(stats["rigid_translation_m"][0]) < 1e-3  # not fitted: about 0, not measured
    assert abs(stats["rigid_translation_m"][1] + 0.1) < 0.01
    # The intersection, seen from its centre, constrains every direction.
    xyz1, xyz2 = intersection_scans()
    assert analysed(xyz1, xyz2)[1]["rigid_unconstrained"] == []


def test_fit_on_exact_planes_recovers_a_known_motion():
    # Voxel means on planes of many orientations, sliding along them (invisible to the fit).
    rng = np.random.default_rng(3)
    mean1 = rng.normal(size=(200, 3)) * 10
    normal = rng.normal(size=(200, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    motion = pose_from_xyzrpy([0.2, -0.1, 0.05, 0.01, -0.02, 0.03])  # maps scan 2 onto scan 1
    slide = 0.5 * np.cross(normal, rng.normal(size=(200, 3)))
    mean2 = apply_pose(np.linalg.inv(motion), mean1 + slide)
    fit = point_to_plane_fit(mean1, mean2, normal, np.full(200, 50.0))
    assert fit.unconstrained == []
    np.testing.assert_allclose(fit.rotation, motion[:3, :3], atol=1e-10)
    np.testing.assert_allclose(fit.translation, motion[:3, 3], atol=1e-10)


def expd_fit(expd, extra: list[float]) -> dict:
    """Statistics of the real ExpD pair, Cloud10 mapped into Cloud1's frame by its reference
    transform (config/expd-T_1_10.txt) with ``extra`` (m) added to its translation."""
    T = read_pose(Path(__file__).resolve().parents[2] / "config" / "expd-T_1_10.txt")
    T[:3, 3] += extra
    xyz1, xyz2 = (read_scan(expd / name).xyz for name in ("Cloud1_ExpD.txt", "Cloud10_ExpD.txt"))
    xyz1, xyz2 = xyz1[np.isfinite(xyz1).all(axis=1)], xyz2[np.isfinite(xyz2).all(axis=1)]
    return analysed(xyz1, apply_pose(T, xyz2), "vlp16")[1]


def test_the_real_expd_pair_sees_an_added_offset_in_part(expd):
    # Measured (stage 0, no mitigation): the reference transform's own fit is
    # (-0.025, -0.330, -0.037) m; +0.3 m along x moves it by (-0.126, -0.027, -0.000) m, -0.3 m
    # by (+0.165, +0.003, -0.011) m. The direction is right but only 40-55% of the offset is
    # recovered: a VLP-16 puts 1 to 4 rings (2 deg apart) in an 8 deg voxel, so many voxels
    # hold a line or two of points whose "normal" is undetermined, and metres-long vectors
    # at the van and at depth edges dominate the field, and the two scans are 3 m apart, so
    # voxel means differ by what each viewpoint sees (measured 2026-11-25: weighting only voxels
    # whose points span more than one beam gap changes nothing, 99% do). The test holds that
    # measured state; realign, on the points, recovers such an offset to 0.4 mm
    # (test_corrections.test_realign_on_the_real_expd_pair_lands_where_it_does_without_an_added_offset).
    base = np.array(expd_fit(expd, [0.0, 0.0, 0.0])["rigid_translation_m"])
    for sign in (1.0, -1.0):
        change = np.array(expd_fit(expd, [sign * 0.3, 0.0, 0.0])["rigid_translation_m"]) - base
        assert -0.35 <= -sign * change[0] and -sign * change[0] >= 0.1
        assert np.abs(change[1:]).max() < 0.05

"""The simulator's calibration faults in a study config: the specs they plan, their errors,
and the default study's stage ids, which they must leave alone."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml

from conftest import ROOT
from lidarfield.commands.jobs import simulated_scan
from lidarfield.errors import ConfigError
from lidarfield.study.config import load_config, validate_config

DEFAULT_CONFIG = ROOT / "config" / "config.yaml"
# A simulated scan's spec before the faults existed: a config without faults keeps exactly these.
SPEC_KEYS = {
    "scene", "sensor", "pose", "time_s", "velocity_mps", "angular_velocity_rps",
    "seed", "range_noise_m", "dropout", "max_range_m", "rolling_shutter",
}  # fmt: skip
# Stage 00's id covers only the pair's inputs (scans' specs and registration): these are the
# ids of the default study before the faults were added to the simulator.
STAGE_00_BEFORE = {"paper-sim": "00-none-654029b4", "drive-000": "00-none-79258dde", "drive-007": "00-none-afd476c0"}


def _default_config() -> dict:
    return yaml.safe_load(DEFAULT_CONFIG.read_text())


def _pair(options: dict | None = None, sensor: str = "paper-sim-80") -> dict:
    sim = {"scene": "paper-intersection", "sensor": sensor, "pose1": [0, 0, 3, 0, 0, 0], "pose2": [1, 1, 3, 0, 0, 0.05]}
    if options is not None:
        sim["options"] = options
    return {"simulate": sim}


def test_the_default_study_keeps_its_specs_and_stage_ids():
    study = load_config(DEFAULT_CONFIG, base_dir=ROOT)
    for scan in study.scans.values():
        assert set(scan.spec) == SPEC_KEYS, scan.id
    for pair, stage_00 in STAGE_00_BEFORE.items():
        assert study.stage_ids(pair)[0] == stage_00


def test_faults_written_as_off_change_no_stage_id():
    unchanged = load_config(DEFAULT_CONFIG, base_dir=ROOT)
    config = _default_config()
    off = {"range_scale": 1, "range_offset_m": 0.0, "elevation_offsets_deg": [0.0] * 80}
    config["pairs"]["paper-sim"]["simulate"]["options"] = {**off, "scan2": {"range_scale": 1.0}}
    config["sequences"]["drive"]["simulate"]["options"].update({**off, "elevation_offsets_deg": None})
    study = validate_config(config, base_dir=ROOT)
    assert sorted(study.pairs) == sorted(unchanged.pairs)
    for pair in unchanged.pairs:
        assert study.stage_ids(pair) == unchanged.stage_ids(pair)


def test_pair_faults_apply_to_both_scans_and_scan2_overrides_them():
    offsets = np.linspace(-0.1, 0.1, 80).tolist()
    options = {"range_offset_m": 0.02, "scan2": {"range_scale": 1.003, "elevation_offsets_deg": offsets}}
    study = validate_config({"pairs": {"p": _pair(options)}})
    spec1, spec2 = study.pairs["p"].scan1.spec, study.pairs["p"].scan2.spec
    assert set(spec1) == SPEC_KEYS | {"range_offset_m"} and spec1["range_offset_m"] == 0.02
    assert set(spec2) == SPEC_KEYS | {"range_offset_m", "range_scale", "elevation_offsets_deg"}
    assert (
        spec2["range_scale"] == 1.003 and spec2["range_offset_m"] == 0.02 and spec2["elevation_offsets_deg"] == offsets
    )
    # a scan1 override beats the options' value; so does one that turns a fault off
    study = validate_config({"pairs": {"p": _pair({"range_scale": 1.01, "scan1": {"range_scale": 1.0}})}})
    assert "range_scale" not in study.pairs["p"].scan1.spec and study.pairs["p"].scan2.spec["range_scale"] == 1.01
    clean = validate_config({"pairs": {"p": _pair()}})
    assert study.stage_ids("p") != clean.stage_ids("p")


def test_sequence_faults_apply_to_every_scan():
    config = _default_config()
    del config["pairs"]
    config["sequences"]["drive"]["simulate"]["options"]["range_scale"] = 1.002
    study = validate_config(config, base_dir=ROOT)
    assert len(study.scans) == 9 and all(s.spec["range_scale"] == 1.002 for s in study.scans.values())


def test_the_job_simulates_the_faults_of_its_spec():
    sensor = {"name": "test-4", "elevation_deg": [-20, -15, -10, -5], "azimuth_resolution_deg": 5.0}
    options = {"range_offset_m": 0.5, "scan2": {"range_scale": 1.01, "elevation_offsets_deg": [0.2, 0, 0, 0]}}
    study = validate_config({"pairs": {"p": _pair(options, sensor=sensor)}})
    clean = simulated_scan(validate_config({"pairs": {"p": _pair(sensor=sensor)}}).pairs["p"].scan2.spec)
    scan2 = simulated_scan(study.pairs["p"].scan2.spec)
    assert "range_scale=1.01 range_offset_m=0.5 elevation_offsets_deg=[0.2, 0.0, 0.0, 0.0]" in scan2.source
    assert np.array_equal(scan2.attributes["ring"], clean.attributes["ring"])
    beams = scan2.attributes["ring"] > 0  # the offset beam hits elsewhere: the others are scaled exactly
    expected = 1.01 * np.linalg.norm(clean.xyz[beams], axis=1) + 0.5
    assert np.allclose(np.linalg.norm(scan2.xyz[beams], axis=1), expected, rtol=0, atol=1e-9)


def _refused(config: dict, *expected: str) -> None:
    with pytest.raises(ConfigError) as e:
        validate_config(config, base_dir=ROOT)
    message = str(e.value)
    assert "\n" not in message, message
    for text in expected:
        assert text in message, message


@pytest.mark.parametrize(
    "options, expected",
    [
        (
            {"elevation_offsets_deg": [0.1, 0.2]},
            "pairs.p.simulate.options.elevation_offsets_deg: need one value per beam of sensor paper-sim-80 "
            "(80 beams), got 2",
        ),
        ({"scan2": {"elevation_offsets_deg": [0.1] * 16}}, "pairs.p.simulate.options.scan2.elevation_offsets_deg"),
        ({"range_scale": 0}, "config key pairs.p.simulate.options.range_scale: 0 is less than or equal"),
        ({"scan1": {"range_scale": -1.0}}, "pairs.p.simulate.options.scan1.range_scale"),
        ({"range_offset_m": "2 cm"}, "pairs.p.simulate.options.range_offset_m: '2 cm' is not of type 'number'"),
        ({"scan3": {"range_scale": 1.01}}, "'scan3' was unexpected"),
        ({"scan2": {"seed": 4}}, "'seed' was unexpected"),
        ({"elevation_offsets_deg": [float("nan")] * 80}, "NaN or infinite"),
    ],
)
def test_bad_faults_are_one_line_errors(options, expected):
    _refused({"pairs": {"p": _pair(options)}}, expected)


def test_a_sequence_has_no_per_scan_faults():
    config = _default_config()
    config["sequences"]["drive"]["simulate"]["options"]["scan2"] = {"range_scale": 1.01}
    _refused(copy.deepcopy(config), "sequences.drive.simulate.options.scan2: per-scan faults are for a pair's")

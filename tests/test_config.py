"""The study config: schema validation, defaults, and the expansion of pairs and sequences."""

from __future__ import annotations

import pytest

from lidarfield.config import SCHEMA_PATH, load_config, validate_config
from lidarfield.errors import InputError, LidarfieldError

from conftest import ROOT


def test_the_package_schema_is_the_workflow_schema():
    assert SCHEMA_PATH.resolve() == (ROOT / "workflow" / "schemas" / "config.schema.yaml").resolve()


def test_defaults_follow_the_kind_of_pair(expd):
    recorded = {"scan1": str(expd / "Cloud1_ExpD.txt"), "scan2": str(expd / "Cloud10_ExpD.txt")}
    simulated = {"simulate": {"scene": "paper-intersection", "sensor": "vlp16", "pose1": [0] * 6, "pose2": [1, 0, 0, 0, 0, 0]}}
    study = validate_config({"pairs": {"real": recorded, "sim": simulated}})
    # Each pair gets its own kind's default, not the other branch's (the schema's oneOf).
    assert study.pairs["real"].register == "identity"
    assert study.pairs["sim"].register == "truth"
    assert study.grid["azimuth_bins"] == 36 and study.grid["min_points"] == 30
    assert study.hypotheses == [] and study.plots["magnification"] == "auto"


def test_a_mat_sequence_becomes_consecutive_pairs(expd, tmp_path):
    entry = {"scans": str(expd / "signagePCs.mat"), "sensor": "vlp16", "stride": 2, "register": "identity"}
    study = validate_config({"sequences": {"sig": entry}})
    assert list(study.pairs) == ["sig-000", "sig-001", "sig-002", "sig-003"]
    assert study.pairs["sig-001"].scan1.spec["path"].endswith("signagePCs.mat#2")
    assert study.pairs["sig-001"].scan2.spec["path"].endswith("signagePCs.mat#4")


def test_a_poses_file_shorter_than_the_sequence_is_refused(expd, tmp_path):
    poses = tmp_path / "poses.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 3)
    entry = {"scans": str(expd / "signagePCs.mat"), "poses": str(poses)}
    with pytest.raises(InputError, match="poses.txt"):
        validate_config({"sequences": {"sig": entry}})


def test_a_simulated_drive_expands_along_its_arc():
    study = load_config(ROOT / "config" / "config.yaml", base_dir=ROOT)
    drive = [p for p in study.pairs if p.startswith("drive-")]
    assert len(drive) == 8
    first, last = study.pairs["drive-000"].scan1.spec, study.pairs["drive-007"].scan2.spec
    assert first["time_s"] == 0.0 and last["time_s"] == pytest.approx(0.8)
    assert abs(last["pose"][0][3] - first["pose"][0][3]) == pytest.approx(8.0, abs=0.1)  # 10 m/s x 0.8 s
    assert first["rolling_shutter"] is True


@pytest.mark.parametrize(
    "config, message",
    [
        ({"pairs": {}, "colour": 1}, "Additional properties are not allowed"),
        ({"pairs": {"a": {"scan1": "nowhere.pcd", "scan2": "nowhere.pcd"}}}, "pairs.a.scan1: file not found"),
        ({"pairs": {}}, "the study has no pairs"),
        ({"pairs": {}, "hypotheses": [{"astrology": {}}]}, "astrology"),
        ({"pairs": {}, "report": {"max_mb": 0}}, r"config key report\.max_mb: 0 is less than or equal to the minimum of 0"),
        ({"pairs": {}, "report": {"max_mb": "x"}}, r"config key report\.max_mb: 'x' is not of type 'number'"),
        ({"pairs": {}, "report": {"max_kb": 5}}, r"config key report: Additional properties are not allowed \('max_kb' was unexpected\)"),
        (
            {"pairs": {"logs": {"simulate": {"scene": "paper-intersection", "sensor": "vlp16", "pose1": [0] * 6, "pose2": [0] * 6}}}},
            r"pair name\(s\) \['logs'\] are folders of the results folder",
        ),
    ],
)
def test_bad_configs_say_what_is_wrong(config, message):
    with pytest.raises(LidarfieldError, match=message):
        validate_config(config)


def test_the_report_budget_is_read_or_defaults_to_20_mb():
    assert validate_config({"report": {"max_mb": 5}}, require_pairs=False).config["report"] == {"max_mb": 5}
    assert validate_config({}, require_pairs=False).config["report"] == {"max_mb": 20}

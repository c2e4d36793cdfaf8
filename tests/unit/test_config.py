"""The study config: schema validation, defaults, and the expansion of pairs and sequences."""

from __future__ import annotations

import pytest
import yaml

from conftest import ROOT
from lidarfield.defaults import SCHEMA_PATH, schema
from lidarfield.errors import InputError, LidarfieldError
from lidarfield.simulation.scene import builtin_scenes
from lidarfield.study.config import load_config, validate_config


def test_the_package_schema_is_the_workflow_schema():
    assert SCHEMA_PATH.resolve() == (ROOT / "workflow" / "schemas" / "config.schema.yaml").resolve()


def test_defaults_follow_the_kind_of_pair(expd):
    recorded = {"scan1": str(expd / "Cloud1_ExpD.txt"), "scan2": str(expd / "Cloud10_ExpD.txt")}
    simulated = {
        "simulate": {"scene": "paper-intersection", "sensor": "vlp16", "pose1": [0] * 6, "pose2": [1, 0, 0, 0, 0, 0]}
    }
    study = validate_config({"pairs": {"real": recorded, "sim": simulated}})
    # Each pair gets its own kind's default, not the other branch's (the schema's oneOf).
    assert study.pairs["real"].register == "identity"
    assert study.pairs["sim"].register == "truth"
    assert study.grid.grid.azimuth_bins == 36 and study.grid.min_points == 30
    assert study.grid_section["azimuth_bins"] == 36 and study.grid_section["cell_m"] == 2.0
    assert study.hypotheses == [] and study.plots.magnification == "auto"


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
        (
            {"pairs": {}, "report": {"max_mb": 0}},
            r"config key report\.max_mb: 0 is less than or equal to the minimum of 0",
        ),
        ({"pairs": {}, "report": {"max_mb": "x"}}, r"config key report\.max_mb: 'x' is not of type 'number'"),
        (
            {"pairs": {}, "report": {"max_kb": 5}},
            r"config key report: Additional properties are not allowed \('max_kb' was unexpected\)",
        ),
        (
            {
                "pairs": {
                    "logs": {
                        "simulate": {
                            "scene": "paper-intersection",
                            "sensor": "vlp16",
                            "pose1": [0] * 6,
                            "pose2": [0] * 6,
                        }
                    }
                }
            },
            r"pair name\(s\) \['logs'\] are folders of the results folder",
        ),
    ],
)
def test_bad_configs_say_what_is_wrong(config, message):
    with pytest.raises(LidarfieldError, match=message):
        validate_config(config)


def test_the_report_budget_is_read_or_defaults_to_20_mb():
    report = validate_config({"report": {"max_mb": 5}}, require_pairs=False).config["report"]
    assert report == {"max_mb": 5, "explorer_points": 50000}
    assert validate_config({}, require_pairs=False).config["report"] == {"max_mb": 20, "explorer_points": 50000}
    report = validate_config({"report": {"explorer_points": 0}}, require_pairs=False).config["report"]
    assert report["explorer_points"] == 0  # every point
    with pytest.raises(LidarfieldError, match="explorer_points"):
        validate_config({"report": {"explorer_points": -1}}, require_pairs=False)


def _simulated(**changes) -> dict:
    simulate = {
        "scene": "paper-intersection",
        "sensor": "vlp16",
        "pose1": [0, 0, 3, 0, 0, 0],
        "pose2": [1, 0, 3, 0, 0, 0],
    }
    return {"pairs": {"a": {"simulate": {**simulate, **changes}}}}


@pytest.mark.parametrize(
    "changes, message",
    [
        (
            {"sensor": {"name": "mine"}},
            "pairs.a.simulate.sensor: sensor model: needs at least 'name' and 'elevation_deg'",
        ),
        ({"sensor": "vlp17"}, "pairs.a.simulate.sensor: unknown sensor 'vlp17'"),
        ({"sensor": "mine.yaml"}, "pairs.a.simulate.sensor: file not found: "),
        ({"scene": "mall"}, "config key pairs.a.simulate.scene: 'mall' is not one of"),
        ({"scene": "mall.yaml"}, "pairs.a.simulate.scene: file not found: "),
        ({"pose1": [0, 0, float("nan"), 0, 0, 0]}, "config key pairs.a.simulate.pose1.2: NaN or infinite"),
    ],
)
def test_a_bad_scene_sensor_or_pose_fails_at_validation_naming_the_config(tmp_path, changes, message):
    config = tmp_path / "study.yaml"
    config.write_text(yaml.safe_dump(_simulated(**changes)))
    with pytest.raises(LidarfieldError) as caught:
        load_config(config, base_dir=tmp_path)
    assert str(caught.value).startswith(f"{config}: ") and message in str(caught.value), caught.value
    assert "\n" not in str(caught.value)


def test_a_sensor_yaml_error_names_the_config_and_the_sensor_file(tmp_path):
    (tmp_path / "mine.yaml").write_text("name: mine\n")
    with pytest.raises(LidarfieldError) as caught:
        validate_config(_simulated(sensor="mine.yaml"), base_dir=tmp_path, source="study.yaml")
    assert str(caught.value) == (
        f"study.yaml: pairs.a.simulate.sensor: {tmp_path / 'mine.yaml'}: sensor model: needs at least 'name' and "
        f"'elevation_deg'"
    )


def test_a_yaml_syntax_error_is_one_line_with_its_place(tmp_path):
    config = tmp_path / "study.yaml"
    config.write_text("grid:\n  azimuth_bins: 36\n  elevation_deg: [-20, 20\nhypotheses: []\n")
    with pytest.raises(LidarfieldError) as caught:
        load_config(config)
    assert str(caught.value) == (
        f"{config}: not valid YAML: line 4, column 11: expected ',' or ']', but got ':' (while parsing a flow sequence)"
    )


def test_the_schema_lists_the_builtin_scenes():
    assert schema()["definitions"]["scene"]["anyOf"][0]["enum"] == builtin_scenes()

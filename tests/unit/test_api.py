"""The flat public API: every exported name resolves, and importing the package stays light."""

import subprocess
import sys

import lidarfield


def test_every_exported_name_resolves():
    for name in lidarfield.__all__:
        assert getattr(lidarfield, name) is not None, name


def loads_open3d(code: str) -> bool:
    code = f"import sys\n{code}\nprint('open3d' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    return out.strip() == "True"


def test_import_does_not_load_open3d():
    # Workflow jobs import the package once each: Open3D (over a second) only where it is used.
    assert not loads_open3d("import lidarfield, lidarfield.cli; lidarfield.cli.build_parser()")


def test_validating_a_config_does_not_load_open3d():
    # Snakemake validates the config at every start, twice per job on a cluster (profiles/slurm).
    study = (
        "{'pairs': {'p': {'simulate': {'scene': 'paper-intersection', 'sensor': 'vlp16', "
        "'pose1': [0, 0, 3, 0, 0, 0], 'pose2': [1, 0, 3, 0, 0, 0]}, "
        "'register': {'method': 'icp', 'guess': 'truth'}}}}"
    )
    code = (
        f"import pathlib, lidarfield.study.config\n"
        f"lidarfield.study.config.validate_config({study}, base_dir=pathlib.Path('.'))"
    )
    assert not loads_open3d(code)
    assert loads_open3d(f"{code}\nimport lidarfield.registration.matching")  # the probe sees it

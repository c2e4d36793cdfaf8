"""The flat public API: every exported name resolves, and importing the package stays light."""

import subprocess
import sys

import lidarfield


def test_every_exported_name_resolves():
    for name in lidarfield.__all__:
        assert getattr(lidarfield, name) is not None, name


def test_import_does_not_load_open3d():
    # Workflow jobs import the package once each: Open3D (over a second) only where it is used.
    code = "import sys, lidarfield, lidarfield.cli; lidarfield.cli.build_parser(); print('open3d' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"

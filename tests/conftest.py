"""Shared fixtures: the real scans in ../shared/data (never copied into this repository)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# The commands the tests start (snakemake's rules call `lidarfield`; snakefmt) come from the
# environment running the tests, also when it is a virtual environment that is not activated.
os.environ["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"
SHARED_DATA = Path(os.environ.get("LIDARFIELD_DATA", ROOT.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The folder of real scans; tests that need it are skipped, with the reason, without it."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not found at {SHARED_DATA} (set LIDARFIELD_DATA)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def expd(shared_data) -> Path:
    return shared_data / "expd-vlp16"

"""A full disk: one line naming the file that could not be written and the space left, a non-zero
exit, no partial file, and after freeing space a rerun that completes with the outputs of a clean
run. On a real full file system (a small tmpfs, mounted when the tests run as root) for
``lidarfield run``, ``explain``, ``report`` and the workflow's jobs (through the job worker)."""

from __future__ import annotations

import errno
import os
import re
import subprocess
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from helpers.workflow import TINY_SENSOR, snakemake, tiny_study, write_study
from lidarfield.cli import main
from lidarfield.errors import StorageError
from lidarfield.io import write_scan
from lidarfield.io.parquet_table import read_table, write_table
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.sensors.models import sensor_model
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene

pytestmark = pytest.mark.slow

# What a job or a command prints when a file finds no room: the file, then the space left.
NO_SPACE = re.compile(r"^lidarfield (\w+): error: (\S+): could not be written: No space left on device \((.+)\)$")
GRID = {"azimuth_bins": 18, "elevation_deg": [-25, 12.5], "elevation_bins": 5, "min_points": 5}


class SmallDisk:
    """A tmpfs mounted with ``options``, and a filler file that leaves a chosen number of bytes
    free."""

    def __init__(self, root: Path, options: str):
        self.root = root
        self.filler = root / "filler"
        result = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(root)], capture_output=True)
        if result.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs: {result.stderr.decode().strip()}")

    def leave_free(self, free_bytes: int) -> None:
        self.free()
        room = os.statvfs(self.root).f_bavail * os.statvfs(self.root).f_frsize
        with open(self.filler, "wb") as f:
            f.write(b"\0" * max(room - free_bytes, 0))

    def free(self) -> None:
        self.filler.unlink(missing_ok=True)

    def unmount(self) -> None:
        subprocess.run(["umount", str(self.root)], check=True)


@pytest.fixture
def mount_small_disk(tmp_path):
    """Mounts a tmpfs (``options``: its size, its inodes) at ``tmp_path/disk``; unmounted after."""
    if os.geteuid() != 0:
        pytest.skip("needs root to mount a small tmpfs")
    mounted = []

    def mount(options: str) -> SmallDisk:
        root = tmp_path / "disk"
        root.mkdir()
        mounted.append(SmallDisk(root, options))
        return mounted[-1]

    yield mount
    for disk in mounted:
        disk.unmount()


@pytest.fixture
def small_disk(mount_small_disk):
    return mount_small_disk("size=64m")


def partial_files(folder: Path) -> list[Path]:
    return list(folder.rglob("*.part"))


def the_error(stderr: str, command: str, folder: Path) -> Path:
    """The one error line of ``stderr`` (logging lines aside): a file under ``folder``."""
    assert "Traceback" not in stderr, stderr
    errors = [line for line in stderr.splitlines() if ": error: " in line]
    assert len(errors) == 1, stderr
    match = NO_SPACE.match(errors[0])
    assert match, errors[0]
    assert match.group(1) == command
    path = Path(match.group(2))
    assert path.is_relative_to(folder) and not path.exists()
    return path


def same_files(reference: Path, folder: Path) -> None:
    """``folder`` holds exactly ``reference``'s files, byte for byte."""
    names = sorted(str(p.relative_to(reference)) for p in reference.rglob("*") if p.is_file())
    assert sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()) == names
    for name in names:
        assert (folder / name).read_bytes() == (reference / name).read_bytes(), name


def test_a_write_that_finds_no_room_raises_one_error_and_leaves_the_old_file(small_disk):
    old = {"x": [1.0, 2.0]}
    path = small_disk.root / "table.parquet"
    write_table(path, {k: np.asarray(v) for k, v in old.items()})
    small_disk.leave_free(100_000)
    noise = np.random.default_rng(0).random(200_000)  # 1.6 MB, incompressible
    with pytest.raises(StorageError) as raised:
        write_table(path, {"x": noise})
    message = str(raised.value)
    assert message.startswith(f"{path}: could not be written: No space left on device (")
    free = float(re.search(r"\((\d+) kB free\)", message).group(1)) * 1e3
    assert 50_000 < free < 150_000  # about what the filler left (tmpfs counts whole pages)
    assert partial_files(small_disk.root) == []
    assert read_table(path)[0]["x"].tolist() == old["x"]  # the old file, whole


def test_over_quota_is_the_same_one_error(tmp_path, monkeypatch):
    """EDQUOT (a spent quota) as ENOSPC, here injected: no tmpfs has quotas."""

    def spent_quota(table, where, **options):
        Path(where).write_bytes(b"PAR1 half a file")
        raise OSError(errno.EDQUOT, "Error writing bytes to file. Detail: [errno 122] Disk quota exceeded")

    monkeypatch.setattr(pq, "write_table", spent_quota)
    path = tmp_path / "table.parquet"
    with pytest.raises(StorageError, match=rf"^{re.escape(str(path))}: could not be written: Disk quota exceeded \("):
        write_table(path, {"x": np.zeros(3)})
    assert list(tmp_path.iterdir()) == []
    # Any other error is not a storage error: left as it is.
    monkeypatch.setattr(pq, "write_table", lambda *a, **k: (_ for _ in ()).throw(OSError(errno.EIO, "I/O error")))
    with pytest.raises(OSError, match="I/O error"):
        write_table(path, {"x": np.zeros(3)})
    assert list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def tiny_scans(tmp_path_factory):
    """A pair of small simulated scans (the tiny 16-channel sensor) and a study for them."""
    folder = tmp_path_factory.mktemp("tiny-scans")
    scene, sensor = load_scene("paper-intersection"), sensor_model(TINY_SENSOR)
    for i, pose in enumerate(([0, 0, 3, 0, 0, 0], [1, 1, 3, 0, 0, 0.05]), start=1):
        write_scan(simulate_scan(scene, sensor, pose_from_xyzrpy(pose)), folder / f"scan{i}.parquet")
    study = {
        "grid": GRID,
        "hypotheses": [{"field_of_view": {}}],
        "suggest": [{"ego_vehicle": {}}, {"field_of_view": {}}],
        "plots": {"background_points": 2000, "interactive": False},
    }
    (folder / "study.yaml").write_text(yaml.safe_dump(study))
    return folder


def lidarfield(capsys, *args: str) -> tuple[int, str]:
    """``lidarfield ARGS`` in this process (as the job worker runs a job): its exit status and
    what it printed on stderr."""
    capsys.readouterr()
    status = main(list(args))
    return status, capsys.readouterr().err


def run_args(scans: Path, out: Path) -> list[str]:
    return [
        "run",
        str(scans / "scan1.parquet"),
        str(scans / "scan2.parquet"),
        "--config",
        str(scans / "study.yaml"),
        "--register",
        "truth",
        "--out",
        str(out),
    ]


def test_lidarfield_run_explain_and_report_on_a_full_disk(small_disk, tiny_scans, tmp_path, capsys):
    reference = tmp_path / "run"  # the folder's name is the pair's, in its files
    assert lidarfield(capsys, *run_args(tiny_scans, reference))[0] == 0
    size = sum(p.stat().st_size for p in reference.rglob("*") if p.is_file())

    out = small_disk.root / "run"
    small_disk.leave_free(size // 2)
    status, stderr = lidarfield(capsys, *run_args(tiny_scans, out))
    assert status == 2
    the_error(stderr, "run", out)
    assert partial_files(small_disk.root) == []
    for table in out.rglob("*.parquet"):
        pq.read_table(table)  # whole, or not there
    small_disk.free()
    assert lidarfield(capsys, *run_args(tiny_scans, out))[0] == 0
    same_files(reference, out)

    # explain: it needs more than what is left; report: a page of the run's results.
    for command, args in (
        (
            "explain",
            [
                str(tiny_scans / "scan1.parquet"),
                str(tiny_scans / "scan2.parquet"),
                "--config",
                str(tiny_scans / "study.yaml"),
                "--register",
                "truth",
                "--out",
                str(small_disk.root / "explain"),
            ],
        ),
        ("report", [str(out), "--out", str(small_disk.root / "report.html")]),
    ):
        small_disk.leave_free(20_000)
        status, stderr = lidarfield(capsys, command, *args)
        assert status == 2, stderr
        the_error(stderr, command, small_disk.root)
        assert partial_files(small_disk.root) == []


def lean_study() -> dict:
    """The tiny study cut to one pair, one hypothesis and no stage figures: its jobs write
    every kind of output (scans, the registered pair, stages, fields, tables, pages)."""
    study = tiny_study()
    study["pairs"] = {"shift": study["pairs"]["shift"]}
    study["hypotheses"] = [{"field_of_view": {}}]
    study["plots"] = {**study["plots"], "pairs": "none"}
    study["suggest_pairs"] = "none"
    return study


def tables(results: Path) -> dict[str, bytes]:
    """The study's Parquet files and stage statistics, by path in the results folder."""
    files = [*results.rglob("*.parquet"), *results.rglob("stats.json")]
    return {str(p.relative_to(results)): p.read_bytes() for p in files}


def test_the_workflows_jobs_on_a_full_disk(small_disk, tmp_path):
    """Through the job worker: each job that found no room fails with one line in its log, the
    run exits non-zero, every table left is whole, and after freeing space the rerun completes
    with every table byte for byte a clean run's."""
    reference = tmp_path / "reference"
    reference.mkdir()
    write_study(reference, lean_study())
    snakemake(reference, "--cores", "2")
    clean = tables(reference / "results")
    # what the run takes on disk: a small file (a log, a benchmark) takes a whole block, and a
    # third of that leaves some job's output no room but its log line room
    size = sum(p.stat().st_blocks * 512 for p in (reference / "results").rglob("*") if p.is_file())

    workdir = tmp_path / "study"  # Snakemake's own files here, the results on the small disk
    workdir.mkdir()
    write_study(workdir, lean_study())
    results = small_disk.root / "results"
    small_disk.leave_free(size // 3)
    proc = snakemake(workdir, "--cores", "2", "--config", f"results={results}", check=False)
    assert proc.returncode != 0
    failed = []
    for log in (results / "logs").rglob("*.log"):
        text = log.read_text()
        assert "Traceback" not in text, f"{log}:\n{text}"
        if ": error: " in text:
            failed.append(the_error(text, "job", results))
    assert failed, proc.stdout + proc.stderr
    assert partial_files(small_disk.root) == []
    left = tables(results)
    assert 0 < len(left) < len(clean)
    for name in left:
        if name.endswith(".parquet"):
            pq.read_table(results / name)

    small_disk.free()
    snakemake(workdir, "--cores", "2", "--config", f"results={results}")
    assert tables(results) == clean


def test_a_folder_that_finds_no_room_is_the_same_one_error(mount_small_disk, tiny_scans, capsys):
    """A write outside the atomic writer (``lidarfield run`` making its folder) on a file
    system with space but no inode left."""
    disk = mount_small_disk("size=8m,nr_inodes=1")  # the root folder's only
    out = disk.root / "run"
    status, stderr = lidarfield(capsys, *run_args(tiny_scans, out))
    assert status == 2
    assert the_error(stderr, "run", disk.root) == out
    assert stderr.strip().endswith("(8.4 MB free, but no file can be made: no inode left)")

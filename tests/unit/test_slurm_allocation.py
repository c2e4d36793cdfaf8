"""The slurm-allocation executor plugin's own decisions (when it polls, the cores an allocation's
Snakemake runs with) and the job worker's socket names and stale-socket clean-up, without a
cluster (tests/workflow/test_slurm.py runs them on one)."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from lidarfield.runner import launch

slurm_allocation = pytest.importorskip("snakemake_executor_plugin_slurm_allocation")
pytest.importorskip("snakemake_executor_plugin_slurm")


def test_snakemake_finds_the_plugin_with_the_slurm_plugins_settings():
    from snakemake_interface_executor_plugins.registry import ExecutorPluginRegistry

    plugin = ExecutorPluginRegistry().get_plugin("slurm-allocation")
    assert plugin.executor is slurm_allocation.Executor
    settings = plugin.settings_cls()
    assert settings.pass_command_as_script is False  # the profile turns it on
    assert settings.init_seconds_before_status_checks == 40


def test_the_plugin_and_the_workflow_name_the_allocation_alike():
    assert slurm_allocation.ALLOCATION_ENV == launch.ALLOCATION_ENV


@pytest.mark.parametrize(
    ("plugin_interval", "unchanged", "expected"),
    [
        (2.0, 0.0, 2.0),  # an allocation just ended or was submitted: the plugin's shortest interval
        (45.0, 5.0, 2.0),  # never sooner than the shortest interval
        (45.0, 300.0, 30.0),  # a tenth of the time nothing changed
        (45.0, 1000.0, 45.0),  # never later than the plugin would poll
    ],
)
def test_the_next_poll_comes_within_a_tenth_of_the_time_nothing_changed(plugin_interval, unchanged, expected):
    assert slurm_allocation.next_poll_s(plugin_interval, unchanged, shortest_s=2) == pytest.approx(expected)


@pytest.mark.parametrize(
    ("resources", "threads", "expected"),
    [({}, 2, 2), ({"cpus_per_task": 8}, 2, 8), ({}, 0, 1)],
)
def test_an_allocations_snakemake_runs_on_the_cpus_its_submission_asks_for(resources, threads, expected):
    job = SimpleNamespace(resources=resources, threads=threads)
    assert slurm_allocation.allocation_cpus(job) == expected


def ended_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_stale_socket_clean_up_removes_only_this_hosts_sockets_of_ended_runs(tmp_path):
    gone = ended_pid()
    stale = tmp_path / f".worker-{launch.HOST}-{gone}"
    live = tmp_path / f".worker-{launch.HOST}-{os.getpid()}"
    other_host = tmp_path / f".worker-{launch.HOST}x-{gone}"  # another node's, same PID
    dashed_host = tmp_path / f".worker-{launch.HOST}-2-{gone}"  # node "HOST-2"
    other_stem = tmp_path / f"lidarfield-slurm-7-{launch.HOST}-{gone}"
    for path in (stale, live, other_host, dashed_host, other_stem):
        path.mkdir()
        (path / launch.SOCKET_NAME).touch()
    launch.remove_stale_sockets(tmp_path, launch.LOCAL_RUN_STEM)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        p.name for p in (live, other_host, dashed_host, other_stem)
    )


def test_a_socket_is_named_after_its_host_and_run_in_a_folder_of_its_own(tmp_path):
    folder = launch.private_folder(tmp_path, "lidarfield-slurm-42", 1234)
    assert launch.socket_path(folder) == str(tmp_path / f"lidarfield-slurm-42-{launch.HOST}-1234" / "socket")
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    # A killed run's folder of the same process id is this user's: used again, made private again.
    folder.chmod(0o755)
    assert launch.private_folder(tmp_path, "lidarfield-slurm-42", 1234) == folder
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700


def test_a_socket_too_deep_for_its_folder_goes_to_the_temporary_folder_else_nowhere(tmp_path, monkeypatch):
    """A socket's path holds 107 bytes: where the worker's would be longer in its folder, its
    private folder goes to the system's temporary folder; where it is too long there too, there
    is no worker."""
    monkeypatch.setattr(launch, "HOST", "node")
    temporary = Path(launch.tempfile.gettempdir())  # short (pytest's tmp_path under xdist is not)
    # The deepest folder that still fits: its name and "/" take the room left in tmp_path.
    room = 107 - len(launch.socket_path(tmp_path / ".worker-node-1234"))
    fits = tmp_path / ("d" * (room - 1))
    assert len(launch.socket_path(fits / ".worker-node-1234")) == 107
    assert launch.socket_place(fits, ".worker", 1234) == (fits, ".worker")
    deeper = Path(f"{fits}x")
    assert launch.socket_place(deeper, ".worker", 1234) == (temporary, launch.TEMP_RUN_STEM)
    monkeypatch.setattr(launch.tempfile, "tempdir", str(deeper))
    assert launch.socket_place(deeper, ".worker", 1234) is None


def test_no_worker_folder_where_another_user_made_one_of_its_name(tmp_path):
    """In a shared temporary folder another user could make the worker's folder first: the
    worker is then not started (its jobs run as plain processes), never in their folder."""
    theirs = tmp_path / f"lidarfield-slurm-42-{launch.HOST}-1234"
    theirs.symlink_to(tmp_path)  # not a folder of its own (and lstat sees that)
    assert launch.private_folder(tmp_path, "lidarfield-slurm-42", 1234) is None


@pytest.mark.skipif(os.getuid() != 0, reason="needs root, to make a folder another user's")
def test_no_worker_folder_in_another_users_folder_of_its_name(tmp_path):
    import pwd

    theirs = tmp_path / f"lidarfield-slurm-42-{launch.HOST}-1234"
    theirs.mkdir()
    theirs.chmod(0o777)
    os.chown(theirs, pwd.getpwnam("nobody").pw_uid, -1)
    assert launch.private_folder(tmp_path, "lidarfield-slurm-42", 1234) is None
    assert stat.S_IMODE(theirs.stat().st_mode) == 0o777  # left as it is

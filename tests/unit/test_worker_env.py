"""The job worker's environment (``runner.launch.worker_env``): one thread for the numeric
libraries, glibc's malloc asked for huge pages unless the user set its tunables, and no worker
socket of its own; and a process started with it runs (glibc takes the tunable)."""

from __future__ import annotations

import subprocess
import sys

from lidarfield.cli.worker_client import ENV
from lidarfield.runner.launch import MALLOC_VARS, THREAD_VARS, worker_env


def test_the_worker_runs_one_thread_with_huge_pages_and_no_socket_of_its_own():
    env = worker_env({"PATH": "/bin", ENV: "/tmp/socket", "OMP_NUM_THREADS": "8"})
    assert env["GLIBC_TUNABLES"] == "glibc.malloc.hugetlb=1"
    assert all(env[name] == "1" for name in THREAD_VARS)
    assert ENV not in env and env["PATH"] == "/bin"


def test_the_users_own_malloc_tunables_win():
    assert worker_env({"GLIBC_TUNABLES": "glibc.malloc.arena_max=2"})["GLIBC_TUNABLES"] == "glibc.malloc.arena_max=2"


def test_a_process_with_the_workers_malloc_settings_runs_numpy():
    out = subprocess.run(
        [sys.executable, "-c", "import numpy; print(int(numpy.ones(1 << 20).sum()))"],
        env={**MALLOC_VARS},
        capture_output=True,
        text=True,
        check=True,
    )
    assert out.stdout.split() == [str(1 << 20)]

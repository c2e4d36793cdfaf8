"""Starting and stopping the job worker of a workflow run (see :mod:`lidarfield.runner.server`).

The workflow spawns it while Snakemake reads the Snakefile (its imports overlap the planning),
points the jobs at it when the run starts executing locally (``start``), and stops it when the
run ends (``stop``).
"""

from __future__ import annotations

import atexit
import os
import subprocess
import sys
import time
from pathlib import Path

from ..cli.worker_client import ENV, worker_socket
from .server import IDLE_TIMEOUT_S

# Numeric libraries start as many threads as these say; jobs run with threads: 1.
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")
# The figure warm-up costs about 1 s of CPU and saves a stage's figure job about 0.2 s: it is
# done for studies with at least this many stage-figure jobs (the default study has 27; a
# one-pair test study's run took 20% longer with it).
WARM_UP_MIN_FIGURE_JOBS = 10
SOCKET_GLOB = ".worker-*.sock"


def socket_path(results: str | Path, owner_pid: int) -> str:
    """The socket of the worker of the workflow run ``owner_pid``, in its results folder; a
    relative path where the absolute one is too long for a Unix socket (108 bytes)."""
    path = Path(results).absolute() / f".worker-{owner_pid}.sock"
    return str(path) if len(str(path)) < 100 else os.path.relpath(path)


def remove_stale_sockets(results: Path) -> None:
    """Sockets left by workers whose workflow run is gone (killed before its onerror)."""
    for path in results.glob(SOCKET_GLOB):
        try:
            os.kill(int(path.name.split("-")[1].split(".")[0]), 0)
        except ProcessLookupError:
            path.unlink(missing_ok=True)
        except (ValueError, PermissionError):
            pass


# The worker of this workflow run (the Snakemake process), from spawn() or start() to stop().
_running: subprocess.Popen | None = None


def spawn(results: str | Path, idle_timeout_s: float = IDLE_TIMEOUT_S, figure_jobs: int = 0) -> subprocess.Popen | None:
    """Start this workflow run's worker importing, without pointing jobs at it yet: called
    while Snakemake reads the Snakefile, its imports overlap Snakemake's planning. ``start``
    then uses it; a run that executes nothing (a dry run, nothing to do) stops it at exit.
    ``figure_jobs``: the study's stage-figure jobs, which decide the figure warm-up (see
    ``WARM_UP_MIN_FIGURE_JOBS``). None when ``LIDARFIELD_WORKER=off``."""
    global _running
    if ENV in os.environ and worker_socket() is None:
        return None
    if _running is None:
        results = Path(results)
        (results / "logs").mkdir(parents=True, exist_ok=True)
        remove_stale_sockets(results)
        path = socket_path(results, os.getpid())
        Path(path).unlink(missing_ok=True)
        env = {**os.environ, **{name: "1" for name in THREAD_VARS}}
        env.pop(ENV, None)
        with open(results / "logs" / "worker.log", "a") as log_file:
            _running = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "lidarfield.runner.server",
                    path,
                    "--parent-pid",
                    str(os.getpid()),
                    "--idle-timeout",
                    str(idle_timeout_s),
                    *(["--warm-up"] if figure_jobs >= WARM_UP_MIN_FIGURE_JOBS else []),
                ],
                stdin=subprocess.DEVNULL,
                stdout=log_file,
                stderr=subprocess.STDOUT,
                env=env,
                start_new_session=True,  # Ctrl-C reaches the jobs through their clients, not the worker
            )
        atexit.register(stop)
    return _running


def start(results: str | Path, idle_timeout_s: float = IDLE_TIMEOUT_S) -> subprocess.Popen | None:
    """Point this workflow run's jobs at its worker (``LIDARFIELD_WORKER``), spawned now if
    ``spawn`` was not called; None, and jobs run as plain processes, when
    ``LIDARFIELD_WORKER=off`` or the worker did not come up."""
    worker = spawn(results, idle_timeout_s)
    if worker is None:
        return None
    path = socket_path(results, os.getpid())
    deadline = time.monotonic() + 10.0
    while not os.path.exists(path) and worker.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    if not os.path.exists(path):
        stop()
        return None  # jobs run as plain processes; the reason is in the worker's log
    os.environ[ENV] = path
    return worker


def stop() -> None:
    """Stop the worker (after the workflow's last job) and let later jobs run in-process."""
    global _running
    worker, _running = _running, None
    if worker is None:
        return
    os.environ.pop(ENV, None)
    worker.terminate()
    try:
        worker.wait(timeout=10)
    except subprocess.TimeoutExpired:
        worker.kill()

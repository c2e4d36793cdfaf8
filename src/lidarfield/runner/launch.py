"""Starting and stopping the job worker of a workflow run (see :mod:`lidarfield.runner.server`).

The workflow spawns it when Snakemake starts planning a run that executes jobs here (its
imports overlap the planning; a dry run, ``--lint``, ``--dag`` or ``--summary`` starts none),
points the jobs at it when the run starts executing locally (``start``), and stops it when the
run ends (``stop``). Inside a SLURM allocation (the ``slurm-allocation`` executor, whose one
Snakemake runs a job group's jobs) it is started while Snakemake reads the Snakefile, since
hooks do not run there, with its socket and log on the node's own storage
(``start_in_allocation``).
"""

from __future__ import annotations

import atexit
import os
import shutil
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from ..cli.worker_client import ENV, worker_socket
from . import scheduling
from .server import IDLE_TIMEOUT_S

# Numeric libraries start as many threads as these say; jobs run with threads: 1.
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")
# glibc's malloc in the worker and the jobs it forks asks for transparent huge pages (read as a
# process starts; a user's own GLIBC_TUNABLES wins): a forked job faults its fresh arrays in by
# 2 MB, not 4 kB. Measured 2026-11-28 (load ~20), 12 field jobs of the drive forked from a warm
# process, 3 runs each: 6,800-9,800 page faults and 31-37 ms of system CPU a job against
# 11,100-12,700 and 36-38 ms; user CPU the same (137-143 ms).
MALLOC_VARS = {"GLIBC_TUNABLES": "glibc.malloc.hugetlb=1"}
# The figure warm-up costs about 1 s of CPU and saves a stage's figure job about 0.2 s: it is
# done for studies with at least this many stage-figure jobs (the default study has 27; a
# one-pair test study's run took 20% longer with it).
WARM_UP_MIN_FIGURE_JOBS = 10
# Set (to 1) in the command of a SLURM allocation by the slurm-allocation executor
# (src/snakemake_executor_plugin_slurm_allocation).
ALLOCATION_ENV = "LIDARFIELD_SLURM_ALLOCATION"
# A socket's name carries the host and the PID of the workflow run that owns it: on a shared
# file system only this host's sockets are ever checked for staleness.
HOST = socket.gethostname()
LOCAL_RUN_STEM = ".worker"


SOCKET_NAME = "socket"
# A Unix socket's path holds at most 107 bytes (108 with its NUL).
MAX_SOCKET_PATH = 107
# The stem of a local run's worker folder in the system's temporary folder, where the results
# folder lies too deep for a socket path (see ``socket_place``).
TEMP_RUN_STEM = "lidarfield-worker"


def private_folder(folder: str | Path, stem: str, owner_pid: int) -> Path | None:
    """A folder in ``folder`` that only this user can enter (0700) for the socket of the worker
    of the workflow run ``owner_pid`` on this host: ``{stem}-{host}-{pid}``. None when one of
    that name exists that is not this user's folder (in a shared temporary folder another user
    could have made it): then there is no worker."""
    path = Path(folder) / f"{stem}-{HOST}-{owner_pid}"
    try:
        path.mkdir(mode=0o700)
    except FileExistsError:  # left by a killed run of the same process id, or not ours
        status = path.lstat()
        if not stat.S_ISDIR(status.st_mode) or status.st_uid != os.getuid():
            return None
        path.chmod(0o700)
        (path / SOCKET_NAME).unlink(missing_ok=True)
    return path


def socket_path(private: str | Path) -> str:
    """The worker's socket in its ``private`` folder, as an absolute path: the jobs connect to
    it from any working directory."""
    return str(Path(private).absolute() / SOCKET_NAME)


def socket_place(folder: Path, stem: str, owner_pid: int) -> tuple[Path, str] | None:
    """Where the worker of the workflow run ``owner_pid`` makes its private folder, and the
    folder's stem: ``folder`` and ``stem``, or, where a socket there would be too long (a deep
    working folder), the system's temporary folder and ``TEMP_RUN_STEM``. A private folder there
    is as safe (see ``private_folder``). None when both are too long: then there is no worker."""
    for place, name in ((folder, stem), (Path(tempfile.gettempdir()), TEMP_RUN_STEM)):
        path = socket_path(place / f"{name}-{HOST}-{owner_pid}")
        if len(os.fsencode(path)) <= MAX_SOCKET_PATH:
            return place, name
    return None


def open_private_log(log: Path):
    """``log`` opened to append, created 0600; None when it is a symlink or not this user's own
    file (in an allocation it lies in a node's shared temporary folder, where another user could
    have placed either)."""
    try:
        fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o600)
    except OSError:  # ELOOP: a symlink
        return None
    info = os.fstat(fd)
    if info.st_uid != os.getuid() or not stat.S_ISREG(info.st_mode):
        os.close(fd)
        return None
    return os.fdopen(fd, "a")


def remove_private_folder(private: Path) -> None:
    """A worker's folder and its socket, if still there."""
    (private / SOCKET_NAME).unlink(missing_ok=True)
    try:
        private.rmdir()
    except FileNotFoundError:
        pass


def remove_stale_sockets(folder: Path, stem: str) -> None:
    """This host's worker folders in ``folder`` whose workflow run is gone (killed before it
    could stop its worker). Another host's are never touched: their PIDs mean nothing here."""
    prefix = f"{stem}-{HOST}-"
    for path in folder.glob(f"{prefix}*"):
        try:
            os.kill(int(path.name[len(prefix) :]), 0)
        except ProcessLookupError:
            try:
                remove_private_folder(path)
            except OSError:
                pass  # not a worker's folder, or another user's: not ours to remove
        except (ValueError, PermissionError):
            pass


# The worker of this workflow run (the Snakemake process) and its socket, from spawn() or
# start() to stop().
_running: subprocess.Popen | None = None
_socket: str | None = None


def executes_here(workflow) -> bool:
    """Whether Snakemake's ``workflow`` is set to run its jobs on this machine: not before it
    knows (while it reads the Snakefile), not when it only reads (``--lint``) or prints the
    plan (``--dag``, ``--summary``: no executor), nor for a dry run or ``--touch``."""
    return workflow.executor_plugin is not None and workflow.local_exec and not (workflow.dryrun or workflow.touch)


def spawn_when_planning(workflow, results: str | Path, figure_jobs: int = 0) -> None:
    """Have Snakemake's ``workflow`` ``spawn`` the worker as it starts planning a run that
    executes here (its imports overlap the planning): the first moment it knows whether the
    run executes anything. A run that only reads or prints the workflow, or a dry run, starts
    no process and writes nothing. Without that moment (another Snakemake), ``start`` spawns
    the worker when the run starts."""
    build_dag = getattr(workflow, "_build_dag", None)
    if build_dag is None:
        return

    def spawn_then_build_dag():
        if executes_here(workflow):
            spawn(results, figure_jobs=figure_jobs)
        return build_dag()

    workflow._build_dag = spawn_then_build_dag


def spawn(results: str | Path, idle_timeout_s: float = IDLE_TIMEOUT_S, figure_jobs: int = 0) -> subprocess.Popen | None:
    """Start this workflow run's worker importing, without pointing jobs at it yet: called
    when Snakemake starts planning (``spawn_when_planning``). ``start`` then uses it; a run
    with nothing to do stops it at exit. ``figure_jobs``: the study's stage-figure jobs, which
    decide the figure warm-up (see ``WARM_UP_MIN_FIGURE_JOBS``). None when
    ``LIDARFIELD_WORKER=off``."""
    results = Path(results)
    return _spawn(results, LOCAL_RUN_STEM, results / "logs" / "worker.log", idle_timeout_s, figure_jobs)


def worker_env(environ) -> dict[str, str]:
    """The worker's environment: ``environ`` with one thread for the numeric libraries, the
    malloc settings unless ``environ`` has its own, and no worker socket of its own."""
    env = {**MALLOC_VARS, **environ, **{name: "1" for name in THREAD_VARS}}
    env.pop(ENV, None)
    return env


def _spawn(folder: Path, stem: str, log: Path, idle_timeout_s: float, figure_jobs: int) -> subprocess.Popen | None:
    """The worker, listening on its socket in ``folder`` (or the temporary folder: see
    ``socket_place``) and logging to ``log``."""
    global _running, _socket
    if ENV in os.environ and worker_socket() is None:
        return None
    if not hasattr(socket, "SO_PEERCRED"):
        return None  # the worker could not tell who connects (not Linux): jobs run as processes
    if _running is None:
        place = socket_place(folder, stem, os.getpid())
        if place is None:
            return None
        folder, stem = place
        folder.mkdir(parents=True, exist_ok=True)
        log.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_sockets(folder, stem)
        private = private_folder(folder, stem, os.getpid())
        if private is None:
            return None
        _socket = socket_path(private)
        env = worker_env(os.environ)
        log_file = open_private_log(log)
        if log_file is None:
            remove_private_folder(private)
            return None
        with log_file:
            _running = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "lidarfield.runner.server",
                    _socket,
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
    return _serve_jobs(spawn(results, idle_timeout_s))


def _serve_jobs(worker: subprocess.Popen | None) -> subprocess.Popen | None:
    """Wait (up to 10 s) for ``worker``'s socket, then point this process's jobs at it."""
    if worker is None:
        return None
    deadline = time.monotonic() + 10.0
    while not os.path.exists(_socket) and worker.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    if not os.path.exists(_socket):
        stop()
        return None  # jobs run as plain processes; the reason is in the worker's log
    os.environ[ENV] = _socket
    return worker


def in_allocation(remote_exec: bool) -> bool:
    """Whether this Snakemake runs a job group's jobs inside a SLURM allocation of the
    slurm-allocation executor (``remote_exec``: Snakemake's ``workflow.remote_exec``)."""
    return remote_exec and os.environ.get(ALLOCATION_ENV) == "1"


def start_in_allocation(results: str | Path, figure_jobs: int = 0) -> subprocess.Popen | None:
    """Start the worker of this SLURM allocation's Snakemake and point its jobs at it: socket
    and log in the node's own temporary folder (``TMPDIR``, which SLURM sites often make a
    per-job one), named after the SLURM job. When the Snakemake exits (hooks do not run in an
    allocation), the worker stops and its log moves to ``results/logs/workers/``.
    ``figure_jobs``: the allocation's stage-figure jobs (see ``spawn``)."""
    job = os.environ.get("SLURM_JOB_ID", f"pid{os.getpid()}")
    node_local = Path(tempfile.gettempdir())
    log = node_local / f"lidarfield-slurm-{job}-worker.log"
    worker = _serve_jobs(_spawn(node_local, f"lidarfield-slurm-{job}", log, IDLE_TIMEOUT_S, figure_jobs))
    # Run when the main thread ends, before Python waits for the other threads: the scheduler's
    # pending re-evaluation timers (see runner.scheduling) would hold the exit for their timespan.
    threading._register_atexit(_end_allocation, log, Path(results) / "logs" / "workers" / f"slurm-{job}.log")
    return worker


def _end_allocation(log: Path, kept_log: Path) -> None:
    scheduling.cancel_pending_rounds()
    stop()
    if log.exists():
        kept_log.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(log, kept_log)


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
        worker.wait()
    remove_private_folder(Path(_socket).parent)

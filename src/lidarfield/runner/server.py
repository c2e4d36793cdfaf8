"""A pre-imported worker for the local workflow's jobs: each job forked from it.

Starting Python and importing numpy, pyarrow, matplotlib, Open3D, ... costs a second or more,
which is most of a short job. The worker pays it once: it imports what the jobs use, listens
on a Unix socket, and for each job (sent by :mod:`lidarfield.cli.worker_client`) forks a child that
takes the job's stdin/stdout/stderr, working directory and environment and runs ``lidarfield
job ...`` in-process, so a crash or a kill stays in its job. It reports the child's exit status
(or the signal that killed it) to the client, and kills the child if the client goes away.

The workflow starts one worker per run as Snakemake plans it, points the jobs at it when the
run starts executing locally, with its socket in a folder of the results folder named after the
Snakemake process (of the temporary folder where the results folder is too deep for a socket's
path), and stops it when the run ends (:mod:`lidarfield.runner.launch`). Only the
user who runs the workflow can reach the socket (0600, in a 0700 folder), and the worker
serves only that user's processes (their user id, from the kernel): a job runs a hypothesis's
plugin code, so another user's request would run their code as this user. The
worker also exits when the process that started it is gone, or after ``idle_timeout_s``
without a job. Its log, with each job's CPU time and peak memory (which
Snakemake's benchmark files cannot see), is ``results/logs/worker.log``. What only later jobs
need (figures, pages) it imports between jobs, in steps, then draws a few figures once
(``runner.warm_up``): see ``PRELOAD_BETWEEN_JOBS``.

Fork safety: the worker is started with one thread per numeric library (the rules declare
``threads: 1``). Its figure warm-up writes and reads Parquet files, which starts Arrow's thread
pools: Arrow starts them anew in a forked child (its fork handlers), and matplotlib and plotly
start none.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import logging
import os
import selectors
import signal
import socket
import struct
import sys
import time
import traceback
from collections.abc import Iterator
from pathlib import Path

from ..cli.worker_client import recv_message, send_message

log = logging.getLogger("lidarfield.worker")

# What the jobs import, loaded once in the worker before it forks anything: what a run's first
# jobs (scans, registration, stages) use.
PRELOAD = (
    "lidarfield.cli.job",
    "lidarfield.commands.jobs",
    "lidarfield.study.summary",
    "lidarfield.registration.matching",  # Open3D
    "lidarfield.analysis.rematch",
    "lidarfield.simulation.raycast",
    "lidarfield.simulation.scene",
    "lidarfield.study.stack",
    "lidarfield.analysis.suggest",
    "scipy.spatial",  # the outliers hypothesis' k-d tree (mitigate and suggest jobs)
)
# What only the figure, page and study jobs import, later in a run: imported between jobs once
# the worker serves, so that the first jobs do not wait for it (0.9 s). Then the worker draws a
# few figures once (runner.warm_up): the plot jobs forked afterwards skip matplotlib's and
# plotly's first-use costs.
PRELOAD_BETWEEN_JOBS = (
    "lidarfield.plots",
    "lidarfield.report",
    "lidarfield.study.tables",
    "pandas",  # the summary job's
)
IDLE_TIMEOUT_S = 900.0


class Worker:
    """The socket loop: accept a job, fork its child, report its status; one thread only."""

    def __init__(self, listener: socket.socket, parent_pid: int, idle_timeout_s: float, warm_up: bool = False):
        self.listener = listener
        self.parent_pid = parent_pid
        self.idle_timeout_s = idle_timeout_s
        self.jobs: dict[int, tuple[socket.socket, float, list[str]]] = {}  # pid -> (client, start, argv)
        self.selector = selectors.DefaultSelector()
        self.wakeup_r, self.wakeup_w = os.pipe()
        self.stopping = False
        self.warm_up = warm_up
        self.between_jobs: Iterator[str] | None = between_jobs(warm_up)
        self.between_jobs_s = 0.0

    def step_between_jobs(self) -> None:
        """One step of ``between_jobs``, while no request waits."""
        started = time.perf_counter()
        try:
            next(self.between_jobs)
            self.between_jobs_s += time.perf_counter() - started
            return
        except StopIteration:
            done = "later imports and figure warm-up" if self.warm_up else "later imports"
            log.info("%s done in %.2f s between jobs", done, self.between_jobs_s)
        except Exception as e:  # a failed warm-up only costs the plot jobs their first-use time
            log.warning("figure warm-up stopped: %s: %s", type(e).__name__, e)
            self.between_jobs.close()
        self.between_jobs = None
        gc.collect()
        gc.freeze()  # what these steps created, out of the jobs' collections too (see preload)

    def serve(self) -> None:
        os.set_blocking(self.wakeup_w, False)
        signal.set_wakeup_fd(self.wakeup_w)
        signal.signal(signal.SIGCHLD, lambda *_: None)  # only to wake the loop up
        signal.signal(signal.SIGTERM, self.stop)
        signal.signal(signal.SIGINT, self.stop)
        self.selector.register(self.listener, selectors.EVENT_READ, "accept")
        self.selector.register(self.wakeup_r, selectors.EVENT_READ, "wakeup")
        last_job = time.monotonic()
        while not self.stopping:
            events = self.selector.select(timeout=0 if self.between_jobs is not None else 1.0)
            for key, _ in events:
                if key.data == "accept":
                    self.accept()
                elif key.data == "wakeup":
                    os.read(self.wakeup_r, 4096)
                else:
                    self.client_gone(key.data)
            self.reap()
            if self.between_jobs is not None and not events:
                self.step_between_jobs()
            if self.jobs:
                last_job = time.monotonic()
            if os.getppid() != self.parent_pid:
                log.info("the workflow (pid %d) is gone: stopping", self.parent_pid)
                break
            if time.monotonic() - last_job > self.idle_timeout_s:
                log.info("no job for %.0f s: stopping", self.idle_timeout_s)
                break
        for pid in self.jobs:
            os.kill(pid, signal.SIGTERM)
        if self.between_jobs is not None:
            self.between_jobs.close()  # removes the warm-up's temporary folder

    def stop(self, signum, frame) -> None:
        self.stopping = True

    def accept(self) -> None:
        conn, _ = self.listener.accept()
        peer_pid, peer_uid = peer_credentials(conn)
        if peer_uid != os.getuid():
            # A job can load a plugin: running another user's request would run their code as
            # this user. Refused before reading anything of it.
            log.warning("refused a connection from another user (uid %d, pid %d)", peer_uid, peer_pid)
            conn.close()
            return
        try:
            conn.settimeout(10.0)  # a client sends its request at once: never block the loop long
            _, fds, _, _ = socket.recv_fds(conn, 1, 3)
            request = recv_message(conn)
            if len(fds) != 3:
                raise ValueError(f"expected 3 file descriptors, got {len(fds)}")
        except (OSError, EOFError, ValueError) as e:
            log.warning("dropped a malformed request: %s", e)
            conn.close()
            return
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            self.run_child(conn, fds, request)  # never returns
        for fd in fds:
            os.close(fd)
        conn.settimeout(None)
        self.jobs[pid] = (conn, time.monotonic(), request["argv"])
        self.selector.register(conn, selectors.EVENT_READ, pid)
        send_message(conn, {"pid": pid})

    def run_child(self, conn: socket.socket, fds: list[int], request: dict) -> None:
        """In the forked child: become the job's process, run it, exit with its status."""
        status = 1
        try:
            signal.set_wakeup_fd(-1)
            for signum in (signal.SIGCHLD, signal.SIGTERM):
                signal.signal(signum, signal.SIG_DFL)
            signal.signal(signal.SIGINT, signal.default_int_handler)
            self.selector.close()
            for sock in (self.listener, conn, *(job[0] for job in self.jobs.values())):
                sock.close()
            os.close(self.wakeup_r)
            os.close(self.wakeup_w)
            for target, fd in enumerate(fds):
                os.dup2(fd, target)
                os.close(fd)
            os.chdir(request["cwd"])
            os.environ.clear()
            os.environ.update(request["env"])
            sys.argv = ["lidarfield", *request["argv"]]
            logging.getLogger().handlers.clear()  # the job configures logging to its stderr
            status = run_job(request["argv"])
        except BaseException:
            traceback.print_exc()
        finally:
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except BaseException:
                    pass
            os._exit(status)

    def client_gone(self, pid: int) -> None:
        """A job's client closed its end (it was killed): kill the job too."""
        conn = self.jobs[pid][0]
        self.selector.unregister(conn)
        log.warning("the client of job %d went away: killing the job", pid)
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass

    def reap(self) -> None:
        while self.jobs:
            try:
                pid, status, usage = os.wait4(-1, os.WNOHANG)
            except ChildProcessError:
                return
            if pid == 0:
                return
            conn, started, argv = self.jobs.pop(pid)
            if os.WIFSIGNALED(status):
                result = {"signal": os.WTERMSIG(status)}
            else:
                result = {"exit": os.waitstatus_to_exitcode(status)}
            log.info(
                "job %d %s: %s, %.2f s wall, %.2f s CPU (%.2f s system), %d page faults, %.0f MB peak",
                pid,
                argv[1] if len(argv) > 1 else "?",
                result,
                time.monotonic() - started,
                usage.ru_utime + usage.ru_stime,
                usage.ru_stime,
                usage.ru_minflt + usage.ru_majflt,
                usage.ru_maxrss / 1024,
            )
            try:
                self.selector.unregister(conn)
            except KeyError:
                pass  # already unregistered: its client went away
            try:
                send_message(conn, result)
            except OSError:
                pass
            conn.close()


def peer_credentials(conn: socket.socket) -> tuple[int, int]:
    """The process id and user id of the process at the other end of ``conn`` (a Unix socket),
    as the kernel saw them when it connected (``SO_PEERCRED``)."""
    credentials = struct.Struct("iII")  # struct ucred: pid_t pid, uid_t uid, gid_t gid
    pid, uid, _ = credentials.unpack(conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, credentials.size))
    return pid, uid


def run_job(argv: list[str]) -> int:
    """``lidarfield ARGV`` in this process, with the exit status ``python -m lidarfield`` gives."""
    from ..cli import run_in_process

    try:
        return run_in_process(argv) or 0
    except SystemExit as e:
        if e.code is None or isinstance(e.code, int):
            return e.code or 0
        print(e.code, file=sys.stderr)
        return 1


def import_module(module: str) -> None:
    try:
        importlib.import_module(module)
    except ImportError as e:  # the jobs that need it will fail with the same error
        log.warning("could not preload %s: %s", module, e)


def preload() -> None:
    for module in PRELOAD:
        import_module(module)
    from ..analysis.suggest import code_digest
    from ..cli import build_parser

    code_digest()  # cached: every field and suggest job digests the package's source (5 ms) otherwise
    build_parser()  # cached: every job parses its argv with this one
    # Out of the collector's sight: a job's first full collection would otherwise walk (and so
    # copy, page by page) the whole inherited heap, 0.15 s of a plot job.
    gc.collect()
    gc.freeze()


def between_jobs(warm_up: bool) -> Iterator[str]:
    """The worker's work between jobs, a short step at a time: the later imports, then (when
    ``warm_up``) the figure warm-up. Each step yields what it did."""
    for module in PRELOAD_BETWEEN_JOBS:
        import_module(module)
        yield module
    if not warm_up:
        return
    from .warm_up import warm_up_steps

    yield from warm_up_steps()


def serve(socket_path: str, parent_pid: int, idle_timeout_s: float = IDLE_TIMEOUT_S, warm_up: bool = False) -> None:
    """Listen on ``socket_path`` at once (clients queue while the imports run), then serve."""

    def stop_while_importing(signum, frame):
        # A run with nothing to do ends while the worker imports. Exit at once: an exception
        # raised here, in the middle of a compiled module's import (Open3D's), comes out as
        # that import failing ("initialization failed"), and the imports would go on.
        # Worker.serve installs its own handler afterwards.
        Path(socket_path).unlink(missing_ok=True)
        log.info("worker %d stopped while importing", os.getpid())
        os._exit(0)

    signal.signal(signal.SIGTERM, stop_while_importing)
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    umask = os.umask(0o177)  # the socket made 0600, with no moment of another mode
    try:
        listener.bind(socket_path)
    finally:
        os.umask(umask)
    try:
        listener.listen(socket.SOMAXCONN)
        started = time.perf_counter()
        preload()
        log.info("worker %d on %s: imports took %.2f s", os.getpid(), socket_path, time.perf_counter() - started)
        Worker(listener, parent_pid, idle_timeout_s, warm_up).serve()
    finally:
        listener.close()
        Path(socket_path).unlink(missing_ok=True)
        log.info("worker %d stopped", os.getpid())


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m lidarfield.runner.server", description=__doc__.split("\n")[0])
    parser.add_argument("socket", help="the Unix socket to listen on")
    parser.add_argument("--parent-pid", type=int, default=os.getppid(), help="stop when this process is gone")
    parser.add_argument(
        "--idle-timeout", type=float, default=IDLE_TIMEOUT_S, help="stop after this many seconds without a job"
    )
    parser.add_argument("--warm-up", action="store_true", help="draw a few figures between jobs first (runner.warm_up)")
    args = parser.parse_args(argv)
    from ..cli import stderr_log_handler

    logging.basicConfig(
        level=logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        datefmt="%H:%M:%S",
        handlers=[stderr_log_handler()],  # its log is in the results folder, which can fill up
    )
    serve(args.socket, args.parent_pid, args.idle_timeout, args.warm_up)


if __name__ == "__main__":
    main()

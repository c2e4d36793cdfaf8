"""The ``lidarfield job`` client: hand one workflow job to the study's pre-imported worker.

A local workflow run starts a worker (:mod:`lidarfield.runner.server`) and names its socket in the
``LIDARFIELD_WORKER`` environment variable. A job then sends its argv, working directory,
environment and its stdin/stdout/stderr file descriptors to the worker, which forks a child
that runs the job in-process with those descriptors, so the job's log is written exactly as
without the worker. The client waits, forwards the signals it receives to the child, and
exits with the child's status. With no worker reachable (a cluster node, the worker turned
off or gone) ``run_on_worker`` returns None and the caller runs the job itself.

This module is imported by every job before anything else: it imports only the standard
library modules Python has already loaded at start, plus ``socket`` and ``json``.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import sys

ENV = "LIDARFIELD_WORKER"
OFF = ("", "0", "off", "false", "no")


def worker_socket() -> str | None:
    """The socket named in ``LIDARFIELD_WORKER``, or None when the worker is off or unset."""
    path = os.environ.get(ENV, "")
    return None if path.strip().lower() in OFF else path


def send_message(sock: socket.socket, message: dict) -> None:
    data = json.dumps(message).encode()
    sock.sendall(len(data).to_bytes(4, "big") + data)


def recv_exact(sock: socket.socket, size: int) -> bytes:
    chunks = []
    while size:
        chunk = sock.recv(min(size, 1 << 20))
        if not chunk:
            raise EOFError("connection closed")
        chunks.append(chunk)
        size -= len(chunk)
    return b"".join(chunks)


def recv_message(sock: socket.socket) -> dict:
    return json.loads(recv_exact(sock, int.from_bytes(recv_exact(sock, 4), "big")))


# Exit status of a job whose worker vanished before reporting it.
LOST = 1


def run_on_worker(argv: list[str]) -> int | None:
    """Run ``lidarfield ARGV`` on the worker and return its exit status; None if no worker
    took the job (then nothing ran and the caller runs it in-process)."""
    path = worker_socket()
    if path is None:
        return None
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.connect(path)
        socket.send_fds(sock, [b"J"], [0, 1, 2])
        send_message(sock, {"argv": argv, "cwd": os.getcwd(), "env": dict(os.environ)})
        started = recv_message(sock)
    except (OSError, EOFError, ValueError):
        sock.close()  # no worker, a stale socket, or a worker that refused: run it here
        return None
    child = started["pid"]

    def forward(signum, frame):
        try:
            os.kill(child, signum)
        except ProcessLookupError:
            pass

    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT):
        signal.signal(signum, forward)
    try:
        ended = recv_message(sock)
    except (OSError, EOFError, ValueError):
        # The worker died with the job still running: stop the orphan, report a failure.
        forward(signal.SIGKILL, None)
        print(f"lidarfield job: the worker ({path}) stopped while the job ran; rerun it", file=sys.stderr)
        return LOST
    finally:
        sock.close()
    if "signal" in ended:
        # Die of the same signal, as the job's own process would have (the shell sees 128+N).
        if ended["signal"] not in (signal.SIGKILL, signal.SIGSTOP):
            signal.signal(ended["signal"], signal.SIG_DFL)
        os.kill(os.getpid(), ended["signal"])
        return 128 + ended["signal"]
    return ended["exit"]

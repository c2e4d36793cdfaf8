"""The ``lidarfield`` command: a thin layer of subcommands over the library.

Each subcommand lives in its own module here and exposes ``add_parser(subparsers)``, which
registers its arguments and sets ``func`` to a callable taking the parsed arguments.
"""

from __future__ import annotations

import functools
import os
import sys

SUBCOMMANDS = ("field", "simulate", "register", "run", "explain", "plot", "report", "compare", "info", "job")


@functools.cache  # 20 ms of argparse: built once in the job worker, which its jobs inherit
def build_parser():
    import argparse
    import importlib

    parser = argparse.ArgumentParser(
        prog="lidarfield",
        description="Discrepancy-vector fields between registered lidar scans, and hypotheses that explain them.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in SUBCOMMANDS:
        importlib.import_module(f"{__name__}.{name}").add_parser(subparsers)
    return parser


def one_blas_thread() -> None:
    """OpenBLAS with one thread, unless the user set ``OPENBLAS_NUM_THREADS``, and only before
    numpy is imported (OpenBLAS reads it once, when it loads). Its default, a thread per core,
    was slower here: its small products (a fit's normal equations) wait for the other thread to
    be scheduled. Measured 2026-11-28 on the 2-core machine under load 14-16, ``bench/explain.py
    120000`` twice in turn: the loop 15.5-15.6 s with OpenBLAS's default, 12.0-12.4 s with one
    thread. The workflow's jobs run with one already (``runner.launch.THREAD_VARS``)."""
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main(argv: list[str] | None = None) -> int:
    one_blas_thread()
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["job"]:
        from .worker_client import run_on_worker

        status = run_on_worker(argv)
        if status is not None:
            return status
    return run_in_process(argv)


def stderr_log_handler():
    """Log lines to stderr; one that finds no room (a job's log is on the disk that filled up)
    is dropped quietly, not reported with a traceback: the command's one error line says what
    happened."""
    import logging

    from ..io.atomic import NO_ROOM

    class StderrHandler(logging.StreamHandler):
        def handleError(self, record):
            error = sys.exc_info()[1]
            if not (isinstance(error, OSError) and error.errno in NO_ROOM):
                super().handleError(record)

    return StderrHandler()


def run_in_process(argv: list[str]) -> int:
    """``lidarfield ARGV`` in this process."""
    import logging

    from ..errors import LidarfieldError
    from ..io.atomic import storage_error

    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        datefmt="%H:%M:%S",
        handlers=[stderr_log_handler()],
    )
    try:
        return args.func(args) or 0
    except (LidarfieldError, OSError) as e:
        error = e if isinstance(e, LidarfieldError) else storage_error(e)
        if error is None:
            raise
        print(f"lidarfield {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

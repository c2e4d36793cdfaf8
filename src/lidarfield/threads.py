"""How many threads a process's own parallel work may use."""

from __future__ import annotations

import os


def usable_threads() -> int:
    """``OMP_NUM_THREADS`` if set (Snakemake and the workflow's worker set it to the rule's
    ``threads``: 1 in a workflow job), else every core the process may use."""
    try:
        threads = int(os.environ.get("OMP_NUM_THREADS", ""))
    except ValueError:
        threads = 0
    return threads if threads > 0 else len(os.sched_getaffinity(0))

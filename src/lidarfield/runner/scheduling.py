"""Working around Snakemake's scheduler where it costs a study its time.

Snakemake's local scheduler ends every scheduling round by starting a ``threading.Timer`` of
``--max-jobs-per-timespan``'s timespan (default 1 s) that starts another round, which starts
another timer: every round that a finishing job triggers begins a chain that ticks until the
run ends, so the rounds per second grow with the jobs done. Each round re-reads the size of
every input of every ready job. On the default study this was 3,947 rounds for 152 jobs and
16 s of Snakemake's own CPU time, and it grows with the square of a study's jobs.

The workstation profile sets a timespan of a minute (the job rate it allows is never
reached), so the chains tick 60 times less often; jobs are still scheduled the moment another
finishes. The timers are not daemon threads, so Python would wait for the last one before
exiting: ``cancel_pending_rounds``, called when the run ends, stops them.
"""

from __future__ import annotations

import threading


def cancel_pending_rounds() -> int:
    """Cancel the scheduler's pending re-evaluation timers (after its last round); returns
    how many were pending."""
    timers = [t for t in threading.enumerate() if isinstance(t, threading.Timer) and t.is_alive()]
    for timer in timers:
        timer.cancel()
    return len(timers)

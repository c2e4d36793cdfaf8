"""Working around Snakemake's scheduler where it costs a study its time.

Snakemake's local scheduler ends every scheduling round by starting a ``threading.Timer`` of
``--max-jobs-per-timespan``'s timespan (default 1 s) that starts another round, which starts
another timer: every round that a finishing job triggers begins a chain that ticks until the
run ends, so the rounds per second grow with the jobs done. Each round re-reads the size of
every input of every ready job. On the default study this was 3,947 rounds for 152 jobs and
16 s of Snakemake's own CPU time, and it grows with the square of a study's jobs.

The workstation profile sets a timespan of a minute (the job rate it allows is never
reached), so the chains tick 60 times less often; jobs are still scheduled the moment another
finishes. That still leaves one chain per job done: on a 1,000-pair drive 3,249 timer threads
were alive a third of the way through, and rounds from them alone grew to about one a job done
a minute (each sizing inputs of the ready jobs and listing the jobs left, so the run's
scheduling cost grew with the square of its jobs). :func:`coalesce_reevaluations` makes the
scheduler keep one pending re-evaluation: a timer that would fire no earlier than one already
pending is not started (any round re-evaluates everything, so one is enough).

The timers are not daemon threads, so Python would wait for the last one before exiting:
``cancel_pending_rounds``, called when the run ends, stops them.
"""

from __future__ import annotations

import threading
import time


def cancel_pending_rounds() -> int:
    """Cancel the scheduler's pending re-evaluation timers (after its last round); returns
    how many were pending."""
    timers = [t for t in threading.enumerate() if isinstance(t, threading.Timer) and t.is_alive()]
    for timer in timers:
        timer.cancel()
    return len(timers)


def coalesce_reevaluations(scheduler_class=None) -> bool:
    """Make Snakemake's ``JobScheduler`` (or ``scheduler_class``) keep at most one pending
    re-evaluation timer (see the module); returns whether it was patched (False when Snakemake
    has no such method, or it already is)."""
    if scheduler_class is None:
        from snakemake.scheduling.job_scheduler import JobScheduler as scheduler_class
    original = getattr(scheduler_class, "_schedule_reevalutation", None)  # sic: Snakemake's name
    if original is None or getattr(original, "coalesced", False):
        return False

    def schedule_reevaluation(self, delay: float) -> None:
        # As Snakemake's: a timer that wakes the scheduling loop; not when one that fires no
        # later is pending.
        due = time.monotonic() + delay
        pending = getattr(self, "_lidarfield_pending", None)
        if pending is not None and pending[0].is_alive() and pending[1] <= due:
            return
        timer = threading.Timer(delay, self._open_jobs.release)
        timer.start()
        self._lidarfield_pending = (timer, due)

    schedule_reevaluation.coalesced = True
    scheduler_class._schedule_reevalutation = schedule_reevaluation
    return True

"""Snakemake's re-evaluation timers: one pending at a time, and cancelled when a run ends."""

from __future__ import annotations

import inspect
import threading

import pytest

from lidarfield.runner.scheduling import cancel_pending_rounds, coalesce_reevaluations


def test_pending_timers_are_cancelled_and_end_without_firing():
    fired = []
    timers = [threading.Timer(60.0, fired.append, args=(k,)) for k in range(3)]
    for timer in timers:
        timer.start()
    assert cancel_pending_rounds() >= 3
    for timer in timers:
        timer.join(timeout=5.0)
    assert not any(t.is_alive() for t in timers) and fired == []


def test_other_threads_are_left_alone():
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait, args=(60.0,))
    thread.start()
    try:
        cancel_pending_rounds()
        assert thread.is_alive()
    finally:
        stop.set()
        thread.join()


class Scheduler:
    """What the patch needs of Snakemake's JobScheduler: the semaphore its loop waits on."""

    def __init__(self):
        self._open_jobs = threading.Semaphore(0)

    def _schedule_reevalutation(self, delay: float) -> None:
        threading.Timer(delay, self._open_jobs.release).start()


def test_reevaluations_are_coalesced_into_one_pending_timer():
    assert coalesce_reevaluations(Scheduler) and not coalesce_reevaluations(Scheduler)  # once
    scheduler = Scheduler()
    before = threading.active_count()
    try:
        for _ in range(50):  # what 50 finished jobs' rounds ask for
            scheduler._schedule_reevalutation(60.0)
        assert threading.active_count() == before + 1
        scheduler._schedule_reevalutation(0.05)  # sooner than the pending one: started too
        assert threading.active_count() == before + 2
        assert scheduler._open_jobs.acquire(timeout=5.0)  # and it wakes the loop
    finally:
        cancel_pending_rounds()


def test_snakemakes_scheduler_has_the_method_the_patch_replaces():
    from snakemake.scheduling.job_scheduler import JobScheduler

    assert callable(getattr(JobScheduler, "_schedule_reevalutation", None))
    source = inspect.getsource(JobScheduler.__init__)
    assert "_open_jobs" in source  # the semaphore the patched timers release


@pytest.fixture(autouse=True)
def _no_timers_left():
    yield
    cancel_pending_rounds()

"""The end of a run cancels Snakemake's pending re-evaluation timers."""

from __future__ import annotations

import threading

from lidarfield.runner.scheduling import cancel_pending_rounds


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

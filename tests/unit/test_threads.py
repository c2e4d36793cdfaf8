"""``usable_threads``: the job's ``OMP_NUM_THREADS``, else the cores the process may use."""

import os

import pytest

from lidarfield.threads import usable_threads


def test_threads_follow_the_jobs_setting(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert usable_threads() == 1
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert usable_threads() == 3


@pytest.mark.parametrize("setting", [None, "", "0", "-2", "two"])
def test_without_a_usable_setting_every_core_the_process_may_use(monkeypatch, setting):
    if setting is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", setting)
    assert usable_threads() == len(os.sched_getaffinity(0))

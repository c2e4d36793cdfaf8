"""What every benchmark here shares: the best of repeated timings, and the machine it ran on."""

from __future__ import annotations

import os
import platform
import time


def best_time(function, repeat: int = 3) -> tuple[float, object]:
    """The shortest of ``repeat`` wall times of ``function()`` (seconds), and its last result."""
    best, result = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - start)
    return best, result


def machine() -> str:
    return (
        f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs, Python {platform.python_version()}"
    )

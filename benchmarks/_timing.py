"""Timing helper for the benchmark scripts: medians of repeated runs after a warm-up."""

from __future__ import annotations

import statistics
import time


def median_seconds(fn, *, repeats: int = 7, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` over ``repeats`` runs after ``warmup`` untimed runs.

    ``fn`` must block until its result is ready (call ``.block_until_ready()`` on JAX output).
    """
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)

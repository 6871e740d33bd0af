"""Timing helpers shared by the benchmarks."""
import time


def python_calibration_us() -> float:
    """Time of sum(range(1000)) [us]: how fast (or loaded) this machine is right now."""
    best = float("inf")
    for _ in range(200):
        t0 = time.perf_counter_ns()
        sum(range(1000))
        best = min(best, (time.perf_counter_ns() - t0) / 1e3)
    return best

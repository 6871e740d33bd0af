"""bench_graph.free_running_from_reports: the free-running figures of a simulator in another process
(issue 26's free-running split) from its /diagnostics reports, as the probe receives them (strings)."""
import pathlib
import sys

import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "benchmarks"))
import bench_graph  # noqa: E402


def report(steps, missed, overruns, latency=None, lateness=None) -> dict:
    """One second's report, its values as winch_platform_sim._report sends them."""
    values = {"steps": str(steps), "missed_deadlines": str(missed), "overruns": str(overruns)}
    for name, s in (("command_latency", latency), ("step_lateness", lateness)):
        p50, p99, top, n = s if s is not None else ("", "", "", 0)
        values.update({f"{name}_p50_us": str(p50), f"{name}_p99_us": str(p99), f"{name}_max_us": str(top),
                       f"{name}_count": str(n)})
    return values


def test_counts_are_the_windows_and_percentiles_the_worst_seconds():
    reports = [report(5000, 2, 0, (300, 900, 1500, 1000), (20, 80, 400, 1000)),      # before the window's first second
               report(6000, 2, 0, (310, 700, 800, 998), (25, 90, 300, 1000)),
               report(7000, 5, 1, (290, 1200, 4000, 995), (30, 200, 900, 999)),
               report(8000, 5, 1, (305, 800, 900, 1000), (22, 70, 100, 1000))]
    f = bench_graph.free_running_from_reports(reports)
    assert f["steps"] == 3000 and f["steps_without_fresh_command"] == 3 and f["periods_skipped_behind"] == 1
    assert f["missed_periods"] == 4 and f["missed_pct"] == pytest.approx(100.0 * 4 / 3001)
    lat = f["latency_state_to_command"]
    assert (lat["p50_us"], lat["p99_us"], lat["max_us"], lat["count"]) == (305.0, 1200.0, 4000.0, 2993)
    assert f["step_lateness"]["p99_us"] == 200.0 and f["step_lateness"]["count"] == 2999


def test_a_second_without_commands_has_no_latency_and_too_few_reports_fail():
    reports = [report(0, 0, 0), report(1000, 1000, 0), report(2000, 2000, 0)]
    f = bench_graph.free_running_from_reports(reports)
    assert f["missed_pct"] == pytest.approx(100.0) and f["latency_state_to_command"]["p99_us"] is None
    with pytest.raises(RuntimeError, match="reports in the window"):
        bench_graph.free_running_from_reports(reports[:1])

"""benchmarks/bench_against.py: a turn's figures come from its own samples only (a stopped graph's
samples before and after the turn do not count), and the interval resamples whole rounds."""
import pathlib
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
import bench_against  # noqa: E402


def samples(t0: float, t1: float, rtf: float, cpu_us: float, step_s: float = 0.05):
    """(time, steps, thread CPU ns) every ``step_s`` over [t0, t1] of a graph running at ``rtf``."""
    out, t = [], t0
    while t <= t1 + 1e-9:
        steps = round((t - t0) * rtf * 1e3)
        out.append((t, steps, int(steps * cpu_us * 1e3)))
        t += step_s
    return out


def test_a_turn_counts_only_its_own_samples():
    settle = bench_against.SETTLE_S
    before = samples(0.0, 1.0, 0.5, 2000.0)
    # stopped from 1.0 to 2.0 (no samples), then a turn of 1 s at RTF 0.8 and 1250 us per period
    turn = [(t, s + before[-1][1], c + before[-1][2]) for t, s, c in samples(2.0, 3.0, 0.8, 1250.0)]
    figures = bench_against.turn_figures(before + turn, 2.0 - settle, 3.0)
    assert figures["rtf"] == pytest.approx(0.8, rel=0.01)
    assert figures["loop_thread_us_per_period"] == pytest.approx(1250.0, rel=0.01)
    # a turn in which the graph did not step gives no figures (not a ratio of zero)
    assert bench_against.turn_figures([(2.0, 5, 0), (2.5, 5, 10)], 1.9, 3.0) is None


def test_ratios_and_the_interval_over_rounds():
    pairs = [{"this": {"rtf": 0.9}, "other": {"rtf": 1.0}}, {"this": {"rtf": 1.1}, "other": {"rtf": 1.0}}]
    assert bench_against.ratios(pairs, "rtf") == pytest.approx([0.9, 1.1])
    # one round far off: resampling rounds (not pairs) puts it into the interval's width
    rounds = [[1.0, 1.01, 0.99]] * 5 + [[0.8, 0.81, 0.79]]
    lo, hi = bench_against.interval(rounds)
    assert lo < 1.0 <= hi
    assert bench_against.interval(rounds) == (lo, hi)            # a fixed seed
    assert bench_against.interval([[1.0, 1.0]] * 4) == (1.0, 1.0)


def test_deliveries_per_period_and_per_node():
    # --deliveries: each sample carries the running totals {subscriber <- topic: (ns, deliveries)}
    a = (1.0, 100, 100_000_000, {"fd <- /setpoint": (1_000_000, 100), "fd <- /wrench": (5_000_000, 100)})
    b = (1.2, 300, 300_000_000, {"fd <- /setpoint": (1_400_000, 300), "fd <- /wrench": (15_000_000, 300),
                                 "jc <- /fd": (2_000_000, 200)})
    figures = bench_against.turn_figures([a, b], 1.0 - bench_against.SETTLE_S, 1.2)
    assert figures["deliveries_us_per_period"] == pytest.approx(
        {"fd <- /setpoint": 2.0, "fd <- /wrench": 50.0, "jc <- /fd": 10.0})   # a subscriber new in the turn: from 0
    # a node computes in the delivery that completes its inputs, another topic in the other tree:
    # the node table sums its topics; what the deliveries leave of the thread's CPU is "outside"
    this = {"rtf": 1.0, "loop_thread_us_per_period": 100.0,
            "deliveries_us_per_period": {"fd <- /setpoint": 60.0, "fd <- /wrench": 1.0, "jc <- /fd": 9.0}}
    other = {"rtf": 1.0, "loop_thread_us_per_period": 90.0,
             "deliveries_us_per_period": {"fd <- /setpoint": 1.0, "fd <- /wrench": 50.0, "jc <- /fd": 9.0}}
    rounds = [{"pairs": [{"this": this, "other": other}]}]
    nodes = {row["delivery"]: row for row in bench_against.delivery_table(rounds)}
    assert nodes["fd"]["difference_us"] == pytest.approx(10.0)
    assert nodes["jc"]["difference_us"] == pytest.approx(0.0)
    assert nodes["(outside the deliveries)"]["this_us"] == pytest.approx(30.0)
    assert nodes["(outside the deliveries)"]["other_us"] == pytest.approx(30.0)
    assert bench_against.delivery_table(rounds)[0]["delivery"] == "fd"          # the largest difference first
    topics = {row["delivery"]: row for row in bench_against.delivery_table(rounds, by_node=False)}
    assert topics["fd <- /setpoint"]["difference_us"] == pytest.approx(59.0)

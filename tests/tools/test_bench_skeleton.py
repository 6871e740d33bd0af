"""The transport floor's skeleton graph (benchmarks/skeleton.py): derived from the running closed-loop
graph, it runs composed with the real graph's messages per period, stamped t_k. (No figures: those
are bench_graph.py's.)"""
import pathlib
import sys
import time

from cdpr_control.ros.intraprocess import IntraProcess
from cdpr_tools.launch import Launcher

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "benchmarks"))
import skeleton  # noqa: E402


def test_skeleton_runs_the_real_graphs_periods(tmp_path):
    spec = skeleton.derive(window_s=0.5, warmup_s=0.2)
    real = {(node, p["topic"]): p["per_period"] for node, entry in spec["nodes"].items()
            for p in entry["publishers"] if p["per_period"]}
    topics = skeleton.per_period_topics(spec)
    # the lockstep ring and the stages between: derived, not listed by hand
    assert {"/winch/state", "/clock", "/setpoint", "/cable_forces", "/winch/command"} <= set(topics)
    assert len(spec["nodes"]) == 12
    assert spec["nodes"][skeleton.SIM]["parameters"]["use_sim_time"] is False
    path = tmp_path / "skeleton.json"
    skeleton.save(spec, path)

    period = spec["period_ns"]
    with Launcher(skeleton.description(path), mode="composed") as launch:
        sim = next(n for n in launch.nodes if n.get_name() == skeleton.SIM)
        deadline = time.monotonic() + 30.0
        while sim.sim.steps < 10:
            assert time.monotonic() < deadline, "the skeleton's lockstep ring did not start"
            time.sleep(0.02)
        watch = skeleton.Publications(launch.nodes, IntraProcess.of(launch.nodes[0].context))
        steps0, watch.on = sim.sim.steps, True
        time.sleep(1.0)
        watch.on = False
        steps1 = sim.sim.steps
        errors = list(launch.errors)
        faults = {n.get_name(): n.input_faults for n in launch.nodes if n.input_faults}
    assert not errors and not faults
    assert steps1 - steps0 > 50                       # the ring advances: simulated time grows
    steps = watch.counts[(skeleton.SIM, "/winch/state")]
    # every per-period topic of the real graph, from the same node, as often per period; nothing else
    assert {key for key, count in watch.counts.items() if count} == set(real)
    for key, n in real.items():
        assert abs(watch.counts[key] - n * steps) <= 2 * n, key
    # stamped t_k: one message per period of the ring, each stamped with its period
    assert set(watch.stamps) == set(real)
    for key, stamps in watch.stamps.items():
        assert all(t % period == 0 for t in stamps), key
        assert all(b - a == period for a, b in zip(stamps, stamps[1:])), key
        assert steps0 * period - 2 * period <= stamps[0] and stamps[-1] <= steps1 * period, key

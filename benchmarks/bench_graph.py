"""Real-time factor of the whole node graph (graphs/closed_loop.yaml), the main job's transport.

The IPAnema 3 Mini holds still at home at 1 kHz in lockstep (no program: the interpreter holds the
set-point and the loop runs anyway), in four configurations measured in the same run: composed
(one process, one EventsExecutor) and processes (one process per node), each with and without
recording every topic. A probe node in a context of its own subscribes to /clock; after a warm-up
the real-time factor is the simulated time advanced over the wall time between two /clock
receptions a fixed window apart. Per period: wall time, CPU time of the processes involved, and the
CPU time of each node (composed: thread CPU time inside its callbacks; processes: the child's CPU
time from /proc). Baseline in the same run: the same control stages and simulator in one Python
loop without ROS (cdpr_sim.closed_loop.run holding home) for as many periods as the composed graph
ran in its window. ``sim_missed_deadlines`` is the simulator's count from its last /diagnostics
status (it reports on change; null: none came while the probe listened, so the count did not change).

Targets of the issue: rtf >= 3 composed, >= 1 processes, recording slowing by <= 10 %.

Writes bench/graph.json. Run: .venv/bin/python benchmarks/bench_graph.py
"""
from __future__ import annotations

import json
import os
import pathlib
import platform
import random
import tempfile
import threading
import time

# a ROS domain of its own, so other graphs on this machine do not feed the probe (set before rclpy)
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.experimental import EventsExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402

from cdpr_control.nodes.qos import DIAGNOSTICS  # noqa: E402
from cdpr_control.nodes.runner import spin  # noqa: E402
from cdpr_control.robot import load_robot  # noqa: E402
from cdpr_sim.closed_loop import hold, run  # noqa: E402
from cdpr_tools.bag import BagReader  # noqa: E402
from cdpr_tools.demo_cmd import GRAPH  # noqa: E402
from cdpr_tools.launch import Launcher, RecordSpec  # noqa: E402
from cdpr_tools.launch_file import load_launch_file  # noqa: E402
from cdpr_tools.ros_graph import new_context  # noqa: E402

ROBOT = "ipanema3_mini"
PERIOD_S = 1e-3
WARMUP_S = 5.0           # wall time after the loop runs, before the window
WINDOW_S = 15.0          # wall time measured
START_TIMEOUT_S = 180.0  # wall time for the graph to start looping (processes: imports, discovery)
SIM_NODE = "/winch_platform_sim"
# one message per control period each; the recorder must hold them all before the window starts
LOOP_TOPICS = ("/winch/state", "/winch/command", "/setpoint", "/cable_forces", "/platform/pose",
               "/platform/wrench", "/forward_kinematics/diagnostics", "/force_distribution",
               "/cable_force_controller/state", "/ospc/state", "/ground_truth/pose", "/ground_truth/twist",
               "/ground_truth/cable_forces", "/ground_truth/external_wrench")
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "graph.json"
TARGETS = {"composed_rtf_min": 3.0, "processes_rtf_min": 1.0, "recording_slowdown_max_pct": 10.0}


class ClockProbe:
    """/clock (and the simulator's /diagnostics) seen from a context and thread of its own."""

    def __init__(self):
        self.context = new_context()
        self.node = Node(f"_bench_graph_probe_{os.getpid()}", context=self.context, start_parameter_services=False)
        self.latest: tuple[float, int] | None = None  # (perf_counter at reception, sim time [ns])
        self.missed_deadlines: int | None = None      # the simulator's count, when it reported one
        clock_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.node.create_subscription(Clock, "/clock", self._on_clock, clock_qos)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, DIAGNOSTICS)
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=spin, args=(self.executor, self._stop), daemon=True)
        self._thread.start()

    def _on_clock(self, msg: Clock) -> None:
        self.latest = (time.perf_counter(), msg.clock.sec * 1_000_000_000 + msg.clock.nanosec)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == SIM_NODE:
                values = {kv.key: kv.value for kv in status.values}
                self.missed_deadlines = int(values.get("missed_deadlines", 0))

    def wait_running(self, timeout: float) -> None:
        """Until /clock has advanced past t = 0 (the lockstep loop runs)."""
        deadline = time.monotonic() + timeout
        while self.latest is None or self.latest[1] <= 0:
            if time.monotonic() > deadline:
                raise TimeoutError(f"the graph did not start looping within {timeout:g} s")
            time.sleep(0.05)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.node.destroy_node()
        self.context.try_shutdown()


class CallbackCpu:
    """Thread CPU time spent in each composed node's subscription and timer callbacks.

    The EventsExecutor looks ``callback`` up on every event, so wrapping it on a running graph works.
    """

    def __init__(self, nodes):
        self.ns: dict[str, int] = {}
        for node in nodes:
            name = node.get_name()
            self.ns[name] = 0
            for entity in [*node.subscriptions, *node.timers]:
                entity.callback = self._timed(name, entity.callback)

    def _timed(self, name: str, callback):
        def timed(*args):
            t0 = time.thread_time_ns()
            try:
                return callback(*args)
            finally:
                self.ns[name] += time.thread_time_ns() - t0
        return timed


def process_cpu_s(pid: int) -> float:
    """utime + stime of a process (every thread), from /proc/<pid>/stat."""
    fields = pathlib.Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(mode: str, record: bool) -> dict:
    description = load_launch_file(GRAPH, {"robot": ROBOT})
    probe = ClockProbe()
    with tempfile.TemporaryDirectory(prefix="bench_graph_") as tmp:
        bag = pathlib.Path(tmp) / "bag"
        description.record = RecordSpec(output=str(bag)) if record else None
        wall_launch = time.perf_counter()
        with Launcher(description, mode=mode) as launch:
            probe.wait_running(START_TIMEOUT_S)
            startup_s = time.perf_counter() - wall_launch
            time.sleep(WARMUP_S)
            if record:  # the window must not start before every loop topic is recorded
                deadline = time.monotonic() + START_TIMEOUT_S
                while not set(LOOP_TOPICS) <= set(launch.recorder.recorded_topics):
                    if time.monotonic() > deadline:
                        raise TimeoutError("the recorder did not subscribe to every loop topic")
                    time.sleep(0.05)
            composed = launch.nodes + ([launch.recorder] if record else [])
            callbacks = CallbackCpu(composed) if mode == "composed" else None
            children = {label: p.pid for label, p in launch.processes.items()}
            cpu0 = time.process_time(), {k: process_cpu_s(pid) for k, pid in children.items()}
            loadavg = os.getloadavg()[0]
            wall0, sim0 = probe.latest
            time.sleep(WINDOW_S)
            wall1, sim1 = probe.latest
            cpu1 = time.process_time(), {k: process_cpu_s(pid) for k, pid in children.items()}
            node_ns = dict(callbacks.ns) if callbacks else None
            errors = list(launch.errors)
        recorded = sum(1 for _ in BagReader(bag).messages(start_ns=sim0, end_ns=sim1)) if record else None
    missed = probe.missed_deadlines
    probe.close()
    if errors:
        raise RuntimeError(f"{mode}: the graph reported errors: {errors}")
    periods = round((sim1 - sim0) * 1e-9 / PERIOD_S)
    wall = wall1 - wall0
    own_cpu = cpu1[0] - cpu0[0]
    child_cpu = {k: cpu1[1][k] - cpu0[1][k] for k in children}
    if node_ns is not None:
        per_node = {k: v * 1e-3 / periods for k, v in node_ns.items()}
    else:
        per_node = {k.rpartition("/")[2]: v * 1e6 / periods for k, v in child_cpu.items()}
    result = {
        "rtf": periods * PERIOD_S / wall,
        "wall_s": wall,
        "sim_s": periods * PERIOD_S,
        "periods": periods,
        "us_per_period": wall * 1e6 / periods,
        "cpu_s": own_cpu + sum(child_cpu.values()),
        "cpu_cores_busy": (own_cpu + sum(child_cpu.values())) / wall,
        "launcher_process_cpu_us_per_period": own_cpu * 1e6 / periods,
        "node_cpu_us_per_period": per_node,
        "startup_s": startup_s,
        "loadavg_1min": loadavg,
        "sim_missed_deadlines": missed,
    }
    if record:
        result["recorded_messages_per_period"] = recorded / periods
    return result


def baseline(periods: int) -> dict:
    """The same stages and simulator, one Python loop, no ROS: cdpr_sim.closed_loop.run holding home."""
    robot = load_robot(ROBOT)
    wall0 = time.perf_counter()
    run(robot, hold(robot.home), periods * PERIOD_S)
    wall = time.perf_counter() - wall0
    return {"rtf": periods * PERIOD_S / wall, "wall_s": wall, "periods": periods, "us_per_period": wall * 1e6 / periods}


def slowdown_pct(plain: dict, recording: dict) -> float:
    return 100.0 * (recording["us_per_period"] / plain["us_per_period"] - 1.0)


def table(result: dict) -> str:
    rows = [f"{'configuration':<22} {'rtf':>6} {'us_per_period':>14} {'periods':>8} {'wall_s':>7} {'cpu_cores':>9} "
            f"{'msgs/period':>11}"]
    for name, r in {**result["configs"], "baseline (no ROS)": result["baseline_in_process"]}.items():
        recorded = r.get("recorded_messages_per_period")
        rows.append(f"{name:<22} {r['rtf']:6.3f} {r['us_per_period']:14.0f} {r['periods']:8d} {r['wall_s']:7.2f} "
                    f"{r.get('cpu_cores_busy', float('nan')):9.2f} {'' if recorded is None else f'{recorded:.2f}':>11}")
    slowdown = result["recording_slowdown_pct"]
    rows.append("recording slowdown: " + ", ".join(f"{k} {v:+.1f} %" for k, v in slowdown.items()))
    for name, r in result["configs"].items():
        nodes = ", ".join(f"{k} {v:.0f}" for k, v in sorted(r["node_cpu_us_per_period"].items(), key=lambda kv: -kv[1]))
        rows.append(f"{name} node CPU [us/period]: {nodes}")
    return "\n".join(rows)


def main() -> None:
    configs = {}
    for mode in ("composed", "processes"):
        for record in (False, True):
            name = mode + ("_recording" if record else "")
            print(f"[bench_graph] {name} ...", flush=True)
            configs[name] = measure(mode, record)
            print(f"[bench_graph] {name}: rtf {configs[name]['rtf']:.3f}", flush=True)
    result = {
        "machine": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "robot": ROBOT,
        "control_period_s": PERIOD_S,
        "warmup_s": WARMUP_S,
        "window_s": WINDOW_S,
        "configs": configs,
        "baseline_in_process": baseline(configs["composed"]["periods"]),
        "recording_slowdown_pct": {m: slowdown_pct(configs[m], configs[f"{m}_recording"])
                                   for m in ("composed", "processes")},
        "targets": TARGETS,
    }
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2))
    print(table(result))
    print(f"[bench_graph] wrote {OUT}")


if __name__ == "__main__":
    main()

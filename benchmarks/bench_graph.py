"""Real-time factor and timing of the whole node graph (graphs/closed_loop.yaml), the main job's transport.

The IPAnema 3 Mini at 1 kHz, every configuration measured in the same run (the machine is shared,
so only figures of one run compare):

- lockstep, holding still at home (no program: the interpreter holds the set-point and the loop
  runs anyway): ``composed`` (one process, in-process delivery), ``composed_dds`` (one process,
  every message over DDS: the transport before intra-process delivery, the baseline),
  ``processes`` (one process per node), ``two_processes`` (simulator | controllers, each composed,
  DDS between them), each plain and (but two_processes) recording every topic;
- type adaptation (cdpr_control.ros.adapted): ``composed`` passes payloads between the nodes (the
  stages' arrays; a ROS message only for whoever needs one), ``composed_messages`` is the message
  path before it (``CDPR_TYPE_ADAPT=0``: every node publishes ROS messages), in-process both, plain,
  recording and on the cuboid program; measured alternately in this run, side by side in
  ``speedup_vs_messages``;
- lockstep on the cuboid program (cuboid_mini), composed and composed_dds;
- free-running at wall-clock 1 kHz (``sync_mode: latest``), composed and composed_dds: the
  simulator's step lateness against its schedule and the latency from publishing winch/state to
  receiving the winch/command of that stamp (p50/p99/max), and missed periods (a step without a
  fresh command, or skipped because the loop fell behind); ``free_running_two_processes``: the same
  across the process boundary (simulator | controllers), the figures from the simulator's
  /diagnostics reports (:func:`free_running_from_reports`).

After a warm-up the real-time factor is the simulated time advanced over the wall time of a
fixed window: composed, read from the simulator node in the process; otherwise a probe node in a
context of its own subscribes to /clock. (Before this session's issue 11 work the probe took
/clock in the composed configurations too, which made the simulator publish /clock over DDS every
period, about 100 us: earlier composed figures carry that.) Per period: wall time, CPU time of the processes involved, and the CPU time of each node
(composed: thread CPU time inside its callbacks, exclusive of the callbacks its publications run
in-process; processes: the child's CPU time from /proc; recording: the bag writer child process
as ``bag_writer_process``, its CPU on the other core counted in the period's CPU). ``baseline_in_process``: the same
control stages and simulator in one Python loop without ROS (cdpr_sim.closed_loop.run holding
home). ``sim_missed_deadlines`` is the simulator's count from its last /diagnostics status.

``transport_floor``: the ceiling the transport allows, the same graph with nodes that compute
nothing (benchmarks/skeleton.py, derived from the running graph: same nodes, topics, message
types, QoS, messages per period and lockstep dependencies, on the same node layer), measured
composed, composed_dds and processes like the graph; the remainder of a target's period over the
floor's is what the real computation may take.

Targets of the issue: rtf >= 3 composed, >= 1 processes, recording slowing by <= 10 %,
free-running <= 0.1 % missed periods and p99 latency <= 500 us.

Writes bench/graph.json. Run: .venv/bin/python benchmarks/bench_graph.py [--quick] [--only CONFIG ...]
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

# a ROS domain of its own, so other graphs on this machine do not feed the probe (set before rclpy)
from cdpr_tools.file_lock import own_ros_domain  # noqa: E402
_DOMAIN_LOCK = own_ros_domain(random.randint(1, 100))   # held for the process: test sessions skip it

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.experimental import EventsExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402

from cdpr_control import programs  # noqa: E402
from cdpr_control.ros import adapted  # noqa: E402
from cdpr_control.ros.intraprocess import IntraProcess  # noqa: E402
from cdpr_control.ros.qos import DIAGNOSTICS  # noqa: E402
from cdpr_control.ros.timing import DurationStats  # noqa: E402
from cdpr_control.ros.runner import spin  # noqa: E402
from cdpr_control.model.robot import load_robot  # noqa: E402
from cdpr_sim.closed_loop import hold, run  # noqa: E402
from cdpr_tools.bag import BagReader  # noqa: E402
from cdpr_tools.demo_cmd import GRAPH  # noqa: E402
from cdpr_tools.launch import LaunchDescription, Launcher, RecordSpec, select_nodes  # noqa: E402
from cdpr_tools.launch_file import load_launch_file  # noqa: E402
from cdpr_tools.program_client import run_program  # noqa: E402
from cdpr_tools.ros_graph import new_context  # noqa: E402

import skeleton  # noqa: E402  (benchmarks/skeleton.py, as the launcher's children import it)

ROBOT = "ipanema3_mini"
PERIOD_S = 1e-3
PERIOD_NS = 1_000_000
WARMUP_S = 5.0           # wall time after the loop runs, before the window
WINDOW_S = 15.0          # wall time measured (lockstep)
# wall time of the second window of a composed configuration holding home, in which every callback
# is timed for the CPU per node (CallbackCpu: two thread clocks a callback, about 50 us a period in
# closed_loop.yaml, which the first window's RTF and CPU per period therefore do not include)
NODE_WINDOW_S = 5.0
FREE_WINDOW_S = 60.0     # wall time measured free-running (the issue's 60 s)
PROGRAM = "cuboid_mini"
START_TIMEOUT_S = 180.0  # wall time for the graph to start looping (processes: imports, discovery)
SIM_NODE = "/winch_platform_sim"
# one message per control period each; the recorder must hold them all before the window starts
LOOP_TOPICS = ("/winch/state", "/winch/command", "/setpoint", "/cable_forces", "/platform/pose",
               "/platform/wrench", "/forward_kinematics/diagnostics", "/force_distribution",
               "/cable_force_controller/state", "/ospc/state", "/ground_truth/pose", "/ground_truth/twist",
               "/ground_truth/cable_forces", "/ground_truth/external_wrench")
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "graph.json"
TARGETS = {"composed_rtf_min": 3.0, "processes_rtf_min": 1.0, "recording_slowdown_max_pct": 10.0,
           "free_running_missed_pct_max": 0.1, "free_running_latency_p99_us_max": 500.0,
           "two_processes_rtf_min": 1.5, "free_running_two_processes_latency_p99_us_max": 1000.0}


class ClockProbe:
    """/clock (and the simulator's /diagnostics) seen from a context and thread of its own."""

    def __init__(self, clock: bool = True):
        """``clock``: subscribe to /clock; otherwise :attr:`sim` (the simulator node in this process,
        set once the graph runs) gives the simulated time."""
        self.context = new_context()
        self.node = Node(f"_bench_graph_probe_{os.getpid()}", context=self.context, start_parameter_services=False)
        self._latest: tuple[float, int] | None = None  # (perf_counter at reception, sim time [ns])
        self.sim = None
        self.missed_deadlines: int | None = None      # the simulator's count, when it reported one
        self.reports: list[dict] = []                 # the simulator's /diagnostics values, in order
        clock_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
        if clock:
            self.node.create_subscription(Clock, "/clock", self._on_clock, clock_qos)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, DIAGNOSTICS)
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=spin, args=(self.executor, self._stop), daemon=True)
        self._thread.start()

    def _on_clock(self, msg: Clock) -> None:
        self._latest = (time.perf_counter(), msg.clock.sec * 1_000_000_000 + msg.clock.nanosec)

    @property
    def latest(self) -> tuple[float, int] | None:
        """(wall time [perf_counter s], simulated time [ns]) of the newest step."""
        if self.sim is not None:
            return time.perf_counter(), self.sim.sim.steps * PERIOD_NS
        return self._latest

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == SIM_NODE:
                values = {kv.key: kv.value for kv in status.values}
                self.missed_deadlines = int(values.get("missed_deadlines", 0))
                self.reports.append(values)

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
    """Thread CPU time spent in each composed node's callbacks, exclusive of nested ones.

    In-process deliveries run inside the callback whose publication started them, so a callback's
    time excludes the callbacks it runs meanwhile (a stack of the running ones). The EventsExecutor
    looks ``callback`` up on every event and the in-process registry on every delivery, so
    wrapping them on a running graph works.
    """

    def __init__(self, nodes, registry: IntraProcess | None):
        self.ns: dict[str, int] = {}
        self._local = threading.local()  # per thread (a recorder over DDS spins its own): the stack
        for node in nodes:
            name = node.get_name()
            self.ns[name] = 0
            for entity in [*node.subscriptions, *node.timers]:
                entity.callback = self._timed(name, entity.callback)
        if registry is not None:
            for topic in registry.topics.values():
                for local in topic.subscriptions:
                    if local.node in nodes:
                        local.callback = self._timed(local.node.get_name(), local.callback)

    def _timed(self, name: str, callback):
        local, ns = self._local, self.ns

        def timed(*args):
            stack = local.__dict__.setdefault("stack", [])  # [name, start of its current slice]
            t0 = time.thread_time_ns()
            if stack:                       # pause the caller
                ns[stack[-1][0]] += t0 - stack[-1][1]
            stack.append([name, t0])
            try:
                return callback(*args)
            finally:
                t1 = time.thread_time_ns()
                ns[name] += t1 - stack.pop()[1]
                if stack:
                    stack[-1][1] = t1
        return timed


def process_cpu_s(pid: int) -> float:
    """utime + stime of a process (every thread), from /proc/<pid>/stat."""
    fields = pathlib.Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def sim_node(launch):
    return next(n for n in launch.nodes if n.get_name() == SIM_NODE.strip("/"))


def start_part(select: list[str], arguments: dict) -> subprocess.Popen:
    """``cdpr launch closed_loop.yaml <select>`` composed, in a process of its own."""
    cmd = [sys.executable, "-c", "import sys; from cdpr_tools.cli import main; sys.exit(main(sys.argv[1:]))",
           "launch", str(GRAPH), *(f"{k}:={v}" for k, v in arguments.items()), *select]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    return subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)


def stop_part(process: subprocess.Popen) -> None:
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGINT)
    try:
        process.wait(30)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()


def measure(mode: str, record: bool = False, intra_process: bool = True, program: str | None = None,
            sync_mode: str = "exact", split: bool = False, window_s: float = WINDOW_S,
            description: LaunchDescription | None = None, type_adapt: bool = True) -> dict:
    """``type_adapt``: the nodes of this process publish payloads (False: ROS messages, as with
    CDPR_TYPE_ADAPT=0); see :func:`measure_graph`."""
    was = adapted.enabled()
    adapted.set_enabled(type_adapt)     # for the whole run: a node chooses at its first publication
    try:
        result = measure_graph(mode, record, intra_process, program, sync_mode, split, window_s, description)
    finally:
        adapted.set_enabled(was)
    result["type_adapt"] = type_adapt
    return result


def measure_graph(mode: str, record: bool, intra_process: bool, program: str | None, sync_mode: str,
                  split: bool, window_s: float, description: LaunchDescription | None) -> dict:
    """One configuration: the window's RTF and CPU per period (untimed callbacks); composed and holding
    home, the CPU per node in a second window (NODE_WINDOW_S); free-running: timing too.
    ``description``: another graph than GRAPH (the skeleton of :func:`transport_floor`; lockstep,
    its simulator node counting its steps in ``sim.steps``)."""
    arguments = {"robot": ROBOT, "sync_mode": sync_mode}
    if description is None:
        description = load_launch_file(GRAPH, arguments)
    part = None
    if split:                               # the simulator in a process of its own
        description = select_nodes(description, exclude=["winch_platform_sim"])
        part = start_part(["--only", "winch_platform_sim"], arguments)
    # composed, the simulator's steps are read in-process: a /clock subscriber in another context
    # would have the simulator publish /clock over DDS every period (about 100 us of its period)
    in_process_clock = mode == "composed" and not split
    # one process per node: the probe (an rclpy context: DDS threads, a spinning thread) starts after
    # the launcher has started its children, which fork with a preexec_fn (PR_SET_PDEATHSIG): a fork
    # beside running threads may deadlock the child before its exec, and Popen then waits for it
    # without bound (the transport floor's processes configuration hung so in session 11's make bench)
    probe = None if mode == "processes" else ClockProbe(clock=not in_process_clock)
    try:
        with tempfile.TemporaryDirectory(prefix="bench_graph_") as tmp:
            bag = pathlib.Path(tmp) / "bag"
            description.record = RecordSpec(output=str(bag)) if record else None
            wall_launch = time.perf_counter()
            with Launcher(description, mode=mode, intra_process=intra_process) as launch:
                if probe is None:
                    probe = ClockProbe(clock=True)
                if in_process_clock:
                    probe.sim = sim_node(launch)
                probe.wait_running(START_TIMEOUT_S)
                startup_s = time.perf_counter() - wall_launch
                time.sleep(WARMUP_S)
                if record:  # the window must not start before every loop topic is recorded
                    deadline = time.monotonic() + START_TIMEOUT_S
                    while not set(LOOP_TOPICS) <= set(launch.recorder.recorded_topics):
                        if time.monotonic() > deadline:
                            raise TimeoutError("the recorder did not subscribe to every loop topic")
                        time.sleep(0.05)
                composed = launch.nodes + ([launch.recorder] if record and mode == "composed" else [])
                registry = IntraProcess.of(launch.nodes[0].context) if mode == "composed" and intra_process else None
                children = {label: p.pid for label, p in launch.processes.items()}
                writer = getattr(getattr(launch.recorder, "writer", None), "pid", None) if record else None
                if writer is not None:          # the recorder's writer child (cdpr_tools.bag.writer_process)
                    children["bag_writer_process"] = writer
                if part is not None:
                    children["winch_platform_sim"] = part.pid
                # free-running: the simulator's own timing figures
                sim = sim_node(launch) if mode == "composed" and not split and sync_mode == "latest" else None
                if sim is not None:
                    counts0 = sim.missed_deadlines, sim.overruns, sim.sim.steps
                    samples0 = len(sim.step_lateness.run), len(sim.command_latency.run)
                reports0 = len(probe.reports)     # (the split's free-running figures: the simulator's reports)
                deliveries0 = registry.deliveries if registry is not None else None
                cpu0 = time.process_time(), {k: process_cpu_s(pid) for k, pid in children.items()}
                loadavg = os.getloadavg()[0]
                wall0, sim0 = probe.latest
                if program is not None:
                    result = run_program(programs.read(program), program, timeout=900.0)
                    if not result.success:
                        raise RuntimeError(f"program {program} failed: {result.message}")
                else:
                    time.sleep(window_s)
                wall1, sim1 = probe.latest
                cpu1 = time.process_time(), {k: process_cpu_s(pid) for k, pid in children.items()}
                deliveries = registry.deliveries - deliveries0 if registry is not None else None
                if sim is not None:
                    counts1 = sim.missed_deadlines, sim.overruns, sim.sim.steps
                    lateness = list(sim.step_lateness.run)[samples0[0]:]
                    latency = list(sim.command_latency.run)[samples0[1]:]
                reports = probe.reports[reports0:] if split and sync_mode == "latest" else None
                node_ns = node_periods = None
                if mode == "composed" and program is None:   # then each node's share, timed (see above)
                    callbacks = CallbackCpu(composed, registry)
                    node_sim0 = probe.latest[1]
                    time.sleep(min(window_s, NODE_WINDOW_S))
                    node_ns, node_periods = dict(callbacks.ns), round((probe.latest[1] - node_sim0) * 1e-9 / PERIOD_S)
                errors = list(launch.errors)
            recorded = sum(1 for _ in BagReader(bag).messages(start_ns=sim0, end_ns=sim1)) if record else None
    finally:
        missed = None if probe is None else probe.missed_deadlines
        if probe is not None:
            probe.close()
        if part is not None:
            stop_part(part)
    if errors:
        raise RuntimeError(f"{mode}: the graph reported errors: {errors}")
    periods = round((sim1 - sim0) * 1e-9 / PERIOD_S)
    wall = wall1 - wall0
    own_cpu = cpu1[0] - cpu0[0]
    child_cpu = {k: cpu1[1][k] - cpu0[1][k] for k in children}
    if node_ns is not None:
        per_node = {k: v * 1e-3 / max(1, node_periods) for k, v in node_ns.items()}
    else:
        per_node = {}
    per_node.update({k.rpartition("/")[2]: v * 1e6 / periods for k, v in child_cpu.items()})
    result = {
        "rtf": periods * PERIOD_S / wall,
        "wall_s": wall,
        "sim_s": periods * PERIOD_S,
        "periods": periods,
        "us_per_period": wall * 1e6 / periods,
        "cpu_s": own_cpu + sum(child_cpu.values()),
        "cpu_cores_busy": (own_cpu + sum(child_cpu.values())) / wall,
        # CPU per period: what the loop costs, less dependent on the other load of a shared machine than rtf
        "cpu_us_per_period": (own_cpu + sum(child_cpu.values())) * 1e6 / periods,
        "launcher_process_cpu_us_per_period": own_cpu * 1e6 / periods,
        "node_cpu_us_per_period": per_node,
        "startup_s": startup_s,
        "loadavg_1min": loadavg,
        "sim_missed_deadlines": missed,
    }
    if deliveries is not None:     # in-process: messages handed to a subscription (each /clock once)
        result["deliveries_per_period"] = deliveries / periods
    if record:
        result["recorded_messages_per_period"] = recorded / periods
    if program is not None:
        result["program"] = program
    if sim is not None:
        missed_steps, overruns, steps = (b - a for a, b in zip(counts0, counts1))
        result["free_running"] = {
            "steps": steps,
            "missed_periods": missed_steps + overruns,
            "missed_pct": 100.0 * (missed_steps + overruns) / max(1, steps + overruns),
            "steps_without_fresh_command": missed_steps,
            "periods_skipped_behind": overruns,
            "step_lateness": DurationStats.summary(lateness),
            "latency_state_to_command": DurationStats.summary(latency),
        }
    if reports is not None:
        result["free_running"] = free_running_from_reports(reports)
    return result


def free_running_from_reports(reports: list[dict]) -> dict:
    """The free-running figures of a simulator in another process, from its /diagnostics reports of
    the window (one a second: cumulative counts, and the step lateness and state -> command latency
    of the second since the previous report). The percentiles are those of the worst second (the
    reports carry no samples): p50 the median over the seconds, p99 and max their maxima."""
    if len(reports) < 2:
        raise RuntimeError(f"the simulator sent {len(reports)} reports in the window (need 2)")
    first, last = reports[0], reports[-1]
    count = lambda key: int(last[key]) - int(first[key])  # noqa: E731
    steps, missed, overruns = count("steps"), count("missed_deadlines"), count("overruns")

    def seconds(name: str) -> dict:
        rows = [r for r in reports[1:] if r.get(f"{name}_count") not in (None, "", "0", 0)]
        if not rows:
            return {"p50_us": None, "p99_us": None, "max_us": None, "count": 0}
        value = lambda r, k: float(r[f"{name}_{k}"])  # noqa: E731
        return {"p50_us": float(np.median([value(r, "p50_us") for r in rows])),
                "p99_us": max(value(r, "p99_us") for r in rows), "max_us": max(value(r, "max_us") for r in rows),
                "count": sum(int(r[f"{name}_count"]) for r in rows), "of": "the worst second's (simulator's reports)"}
    return {
        "steps": steps,
        "missed_periods": missed + overruns,
        "missed_pct": 100.0 * (missed + overruns) / max(1, steps + overruns),
        "steps_without_fresh_command": missed,
        "periods_skipped_behind": overruns,
        "step_lateness": seconds("step_lateness"),
        "latency_state_to_command": seconds("command_latency"),
    }


FLOOR_CONFIGS = {  # the skeleton's configurations: name -> measure() arguments, in the order run
    "composed": dict(mode="composed"),
    "composed_dds": dict(mode="composed", intra_process=False),
    "processes": dict(mode="processes"),
}
FLOOR_LABEL = "same graph, nodes computing nothing (transport floor)"


def transport_floor(window_s: float = WINDOW_S, configs: tuple[str, ...] = tuple(FLOOR_CONFIGS)) -> dict:
    """The ceiling the transport allows: the graph's skeleton (benchmarks/skeleton.py, derived from the
    running graph: same nodes, topics, types, QoS, messages per period and lockstep dependencies on
    the same node layer, the nodes computing nothing) measured like the graph itself."""
    result: dict = {"what": FLOOR_LABEL, "configs": {}, "failed": {}}
    with tempfile.TemporaryDirectory(prefix="bench_graph_floor_") as tmp:
        path = pathlib.Path(tmp) / "skeleton.json"   # the children of the processes configuration read it
        spec = skeleton.derive(ROBOT)
        skeleton.save(spec, path)
        topics = skeleton.per_period_topics(spec)
        result.update(nodes=len(spec["nodes"]), messages_per_period=sum(topics.values()),
                      deliveries_per_period=spec["window"]["deliveries_per_period"], topics_per_period=topics)
        for name in configs:
            print(f"[bench_graph] transport floor {name} ...", flush=True)
            kwargs = FLOOR_CONFIGS[name]
            try:
                if bounded(kwargs):
                    r = bounded_measure(kwargs, window_s, skeleton_path=str(path))
                else:
                    r = measure(**kwargs, window_s=window_s, description=skeleton.description(path, spec))
            except (TimeoutError, RuntimeError) as exc:
                result["failed"][name] = f"{type(exc).__name__}: {exc}"
                print(f"[bench_graph] transport floor {name}: failed: {result['failed'][name]}", flush=True)
                continue
            result["configs"][name] = r
            print(f"[bench_graph] transport floor {name}: rtf {r['rtf']:.3f}", flush=True)
    return result


# wall time a configuration run in a child process (bounded_measure) may take: start-up
# (START_TIMEOUT_S), warm-up, the window and the second one, the launcher's stop (about 20 s), margin
CHILD_MARGIN_S = 120.0


def bounded(kwargs: dict) -> bool:
    """Whether a configuration starts node processes (run by :func:`bounded_measure`)."""
    return kwargs.get("mode") == "processes" or bool(kwargs.get("split"))


def bounded_measure(kwargs: dict, window_s: float, skeleton_path: str | None = None) -> dict:
    """:func:`measure` in a child process of its own, killed with every process it started when it
    has not finished within its bound (START_TIMEOUT_S + WARMUP_S + 2 window_s + CHILD_MARGIN_S):
    a configuration that cannot finish is reported (TimeoutError) and the benchmark goes on.
    ``skeleton_path``: the transport floor's skeleton (skeleton.json) instead of the graph."""
    bound = START_TIMEOUT_S + WARMUP_S + 2.0 * window_s + CHILD_MARGIN_S
    with tempfile.TemporaryDirectory(prefix="bench_graph_child_") as tmp:
        out = pathlib.Path(tmp) / "result.json"
        job = {"kwargs": kwargs, "window_s": window_s, "skeleton": skeleton_path, "out": str(out)}
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
        child = subprocess.Popen([sys.executable, str(pathlib.Path(__file__).resolve()), "--child", json.dumps(job)],
                                 env=env, stdin=subprocess.DEVNULL, start_new_session=True)
        try:
            child.wait(bound)
        except subprocess.TimeoutExpired:
            kill_tree(child.pid)
            child.wait()
            raise TimeoutError(f"did not finish within {bound:g} s (killed with the processes it started)") from None
        if not out.exists():
            raise RuntimeError(f"the measuring process ended with code {child.returncode} without a result")
        answer = json.loads(out.read_text())
    if "error" in answer:
        raise RuntimeError(answer["error"])
    return answer["result"]


def descendants(pid: int) -> list[int]:
    """Every process below pid (children in sessions of their own included), from /proc."""
    parents: dict[int, list[int]] = {}
    for stat in pathlib.Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rpartition(")")[2].split()
        except OSError:                     # ended meanwhile
            continue
        parents.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    found, todo = [], [pid]
    while todo:
        for child in parents.get(todo.pop(), ()):
            found.append(child)
            todo.append(child)
    return found


def kill_tree(pid: int) -> None:
    """SIGKILL pid and every process below it (collected first: killed, their children would be re-parented)."""
    for p in [pid, *descendants(pid)]:
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass


def child_main(job: dict) -> None:
    """The child of :func:`bounded_measure`: one configuration, its result (or error) as JSON."""
    kwargs = dict(job["kwargs"])
    if job["skeleton"] is not None:
        kwargs["description"] = skeleton.description(job["skeleton"])
    try:
        answer = {"result": measure(**kwargs, window_s=job["window_s"])}
    except (TimeoutError, RuntimeError) as exc:
        answer = {"error": f"{type(exc).__name__}: {exc}"}
    pathlib.Path(job["out"]).write_text(json.dumps(answer))


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
    rows = [f"{'configuration':<28} {'rtf':>6} {'us_per_period':>14} {'cpu_us/period':>14} {'periods':>8} "
            f"{'wall_s':>7} {'cpu_cores':>9} {'msgs/period':>11}"]

    def row(name: str, r: dict) -> str:
        recorded = r.get("recorded_messages_per_period")
        return (f"{name:<28} {r['rtf']:6.3f} {r['us_per_period']:14.0f} {r.get('cpu_us_per_period', float('nan')):14.0f} "
                f"{r['periods']:8d} {r['wall_s']:7.2f} "
                f"{r.get('cpu_cores_busy', float('nan')):9.2f} {'' if recorded is None else f'{recorded:.2f}':>11}")
    for name, r in result["configs"].items():
        rows.append(row(name, r))
    if "baseline_in_process" in result:
        rows.append(row("baseline (no ROS)", result["baseline_in_process"]))
    floor = result.get("transport_floor")
    floor_configs = {f"floor {name}": r for name, r in (floor or {}).get("configs", {}).items()}
    if floor is not None:
        rows.append(f"{floor['what']}: {floor['nodes']} nodes, {floor['messages_per_period']} messages and "
                    f"{floor['deliveries_per_period']:.0f} in-process deliveries per period")
        rows.extend(row(name, r) for name, r in floor_configs.items())
    slowdown = result.get("recording_slowdown_pct", {})
    if result["configs"]:
        rows.append("recording slowdown: " + ", ".join(f"{k} {v:+.1f} %" for k, v in slowdown.items()))
    for name, r in result["configs"].items():
        if "free_running" in r:
            f = r["free_running"]
            lat, late = f["latency_state_to_command"], f["step_lateness"]
            fmt = lambda s: "/".join("-" if s[k] is None else f"{s[k]:.0f}" for k in ("p50_us", "p99_us", "max_us"))  # noqa: E731
            rows.append(f"{name}: missed {f['missed_periods']} of {f['steps']} ({f['missed_pct']:.2f} %), "
                        f"latency state->command p50/p99/max {fmt(lat)} us, step lateness {fmt(late)} us")
    for name, r in {**result["configs"], **floor_configs}.items():
        nodes = ", ".join(f"{k} {v:.0f}" for k, v in sorted(r["node_cpu_us_per_period"].items(), key=lambda kv: -kv[1]))
        rows.append(f"{name} node CPU [us/period]: {nodes}")
    return "\n".join(rows)


CONFIGS = {  # name -> measure() arguments, in the order run
    "composed_dds": dict(mode="composed", intra_process=False),
    "composed_dds_recording": dict(mode="composed", intra_process=False, record=True),
    "composed_messages": dict(mode="composed", type_adapt=False),
    "composed": dict(mode="composed"),
    "composed_messages_recording": dict(mode="composed", record=True, type_adapt=False),
    "composed_recording": dict(mode="composed", record=True),
    "processes": dict(mode="processes"),
    "processes_recording": dict(mode="processes", record=True),
    "two_processes": dict(mode="composed", split=True),
    "composed_dds_cuboid": dict(mode="composed", intra_process=False, program=PROGRAM),
    "composed_messages_cuboid": dict(mode="composed", program=PROGRAM, type_adapt=False),
    "composed_cuboid": dict(mode="composed", program=PROGRAM),
    "composed_messages_cuboid_recording": dict(mode="composed", program=PROGRAM, record=True, type_adapt=False),
    "composed_cuboid_recording": dict(mode="composed", program=PROGRAM, record=True),
    "free_running_dds": dict(mode="composed", intra_process=False, sync_mode="latest"),
    "free_running": dict(mode="composed", sync_mode="latest"),
    "free_running_two_processes": dict(mode="composed", split=True, sync_mode="latest"),
}
RECORDING_PAIRS = {"composed": "composed_recording", "composed_dds": "composed_dds_recording",
                   "composed_messages": "composed_messages_recording",
                   "processes": "processes_recording", "composed_cuboid": "composed_cuboid_recording",
                   "composed_messages_cuboid": "composed_messages_cuboid_recording"}
TYPE_ADAPT_PAIRS = (("composed", "composed_messages"), ("composed_recording", "composed_messages_recording"),
                    ("composed_cuboid", "composed_messages_cuboid"),
                    ("composed_cuboid_recording", "composed_messages_cuboid_recording"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter windows (free-running 15 s), for a check")
    parser.add_argument("--child", help=argparse.SUPPRESS)     # bounded_measure's child: its job as JSON
    parser.add_argument("--only", nargs="+", choices=sorted(CONFIGS) + ["transport_floor"],
                        help="run only these configurations (transport_floor: the skeleton's, see transport_floor())")
    args = parser.parse_args()
    if args.child is not None:
        child_main(json.loads(args.child))
        return
    window = 5.0 if args.quick else WINDOW_S
    free_window = 15.0 if args.quick else FREE_WINDOW_S
    configs, failed = {}, {}
    for name, kwargs in CONFIGS.items():
        if args.only and name not in args.only:
            continue
        print(f"[bench_graph] {name} ...", flush=True)
        w = free_window if name in ("free_running", "free_running_two_processes") else window
        try:
            configs[name] = bounded_measure(kwargs, w) if bounded(kwargs) else measure(**kwargs, window_s=w)
        except (TimeoutError, RuntimeError) as exc:   # recorded, and the other configurations still run
            failed[name] = f"{type(exc).__name__}: {exc}"
            print(f"[bench_graph] {name}: failed: {failed[name]}", flush=True)
            continue
        print(f"[bench_graph] {name}: rtf {configs[name]['rtf']:.3f}", flush=True)
    floor = transport_floor(window) if not args.only or "transport_floor" in args.only else None
    reference = configs.get("composed") or next(iter(configs.values()), None)
    result = {
        "machine": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "robot": ROBOT,
        "plant": "winch_platform_sim as graphs/closed_loop.yaml configures it; controllers on the nominal robot file",
        "control_period_s": PERIOD_S,
        "warmup_s": WARMUP_S,
        "window_s": window,
        "free_running_window_s": free_window,
        "configs": configs,
        **({"baseline_in_process": baseline(reference["periods"])} if reference is not None else {}),
        "speedup_vs_dds": {name: configs[name]["rtf"] / configs[base]["rtf"]
                           for name, base in (("composed", "composed_dds"), ("composed_recording", "composed_dds_recording"),
                                              ("composed_cuboid", "composed_dds_cuboid"))
                           if name in configs and base in configs},
        "speedup_vs_messages": {name: configs[name]["rtf"] / configs[base]["rtf"] for name, base in TYPE_ADAPT_PAIRS
                                if name in configs and base in configs},
        "recording_slowdown_pct": {plain: slowdown_pct(configs[plain], configs[rec])
                                   for plain, rec in RECORDING_PAIRS.items() if plain in configs and rec in configs},
        "failed": failed,
        "targets": TARGETS,
    }
    if floor is not None:
        result["transport_floor"] = floor
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2))
    print(table(result))
    print(f"[bench_graph] wrote {OUT}")


if __name__ == "__main__":
    main()

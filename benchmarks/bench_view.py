"""What `cdpr view` costs the 1 kHz loop: unwatched nothing, watched one topic a little.

The IPAnema 3 Mini holds still at home in lockstep (graphs/closed_loop.yaml, composed in this
process, the simulator's default mismatched plant, as `cdpr launch` runs it). One graph is started
and measured in consecutive windows, the configurations alternating (ROUNDS rounds, pattern below)
so that every window of the view has a window without it next to it on each side:

- ``without``: the graph alone (the baseline);
- ``unwatched``: `cdpr view` running in a process of its own, no Foxglove client connected;
- ``cable_forces``: the same with a Foxglove WebSocket client (a process of its own, the protocol's
  ``subscribe`` op, as Foxglove sends it) subscribed to /cable_forces only, receiving every message;
- ``dds_cable_forces``: no view, a plain rclpy subscriber (a process of its own, serialized
  messages, as the bridge subscribes) to /cable_forces: what any subscriber outside the graph's
  process costs, to tell the view's share from the transport's.

A round is ``unwatched, cable_forces, unwatched, without, dds_cable_forces, without``.

Per window: the real-time factor (simulated time, read from the simulator node in this process, over
wall time) and the CPU time of this process (the graph) per simulated period. A configuration's
ratio in a round is its windows' mean figure over the mean of the three ``without`` windows that
begin, split and end the round; the result is the median over the rounds. The unwatched window
starts once the view's start is over (its process idle for two seconds). On a shared machine the
RTF follows the load of the moment and the scheduler (docs/visualization.md: at a load of 20-40 any
subscriber outside the process raised it 1.2-13x); the graph's CPU per period does much less, so
both are reported: the RTF is the issue's figure, the CPU per period says what the view costs the
loop's own process. The view's and the client's processes run on the same two cores and take their
share of them, which the RTF includes and the CPU per period does not.

Two counts in the graph's process say where a watched topic's cost goes, whatever the load: per
period, the DDS copies of in-process messages that its subscriptions' DDS readers hand to Python
(``dds_copies_per_period``: ``LocalSubscription.from_dds`` calls, which drop them,
cdpr_control/ros/intraprocess.py), and the thread CPU time spent writing to DDS
(``dds_publish_us_per_period``: ``IntraProcessPublisher.to_dds``, encoding the CDR and writing it
to the DDS readers, on the publishing thread unless Fast DDS publishes asynchronously:
docs/visualization.md).

Targets (issue 27): unwatched within 5 % of the baseline's RTF, one topic watched within 10 %.
Writes bench/view.json. Run: .venv/bin/python benchmarks/bench_view.py [--rounds N]
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import random
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time

from cdpr_tools.file_lock import own_ros_domain  # noqa: E402
_DOMAIN_LOCK = own_ros_domain(random.randint(1, 100))   # held for the process: test sessions skip it
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

WARMUP_S = 5.0      # wall time after the loop runs, before the first window
WARMUP_SIM_S = 1.0  # ... and at least this much simulated time (the first periods are slow)
SETTLE_S = 5.0      # wall time after a change of configuration (the view and the graph discover each other)
IDLE_CPU = 0.05     # the view has started when its process takes less than this [s of CPU a second]
WINDOW_S = 8.0      # wall time of a window
ROUNDS = 4
TOPIC = "/cable_forces"
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
CONFIGS = ("without", "unwatched", "cable_forces", "dds_cable_forces")
MESSAGE_DATA = 0x01  # the server's binary opcode of a message on a subscribed channel
TARGETS = {"unwatched_rtf_ratio_min": 0.95, "one_topic_rtf_ratio_min": 0.90}
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "view.json"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def child_env() -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}


def watch(port: int, topic: str) -> None:
    """The client process (``--watch PORT TOPIC``): a Foxglove WebSocket client subscribed to one
    topic; prints ``subscribed`` once it is, and on SIGTERM the number of messages it received."""
    from websockets.sync.client import connect

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    deadline = time.monotonic() + 60
    while True:                      # the view listens once it has started
        try:
            ws = connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, open_timeout=30)
            break
        except ConnectionRefusedError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
    with ws:
        channel = None
        while channel is None:       # advertised once the view discovered the topic
            data = ws.recv(timeout=max(0.1, deadline - time.monotonic()))
            if isinstance(data, str) and json.loads(data).get("op") == "advertise":
                channel = next((c["id"] for c in json.loads(data)["channels"] if c["topic"] == topic), None)
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel}]}))
        received = 0
        print("subscribed", flush=True)
        while not stop.is_set():
            try:
                data = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            if isinstance(data, bytes) and data[0] == MESSAGE_DATA:
                received += 1
    print(received, flush=True)


def subscribe(topic: str) -> None:
    """The plain subscriber process (``--subscribe TOPIC``): an rclpy node subscribed to ``topic``
    (serialized, QoS adapted to the publishers); prints ``subscribed`` once it is, and on SIGTERM the
    number of messages it received."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from cdpr_tools.message_convert import message_class
    from cdpr_tools.ros_graph import adapted_qos, new_context, topic_types

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    context = new_context()
    node = Node(f"_bench_view_subscriber_{os.getpid()}", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    deadline = time.monotonic() + 60
    while topic not in topic_types(node) or node.count_publishers(topic) == 0:
        if time.monotonic() > deadline:
            raise TimeoutError(f"no publisher of {topic}")
        executor.spin_once(timeout_sec=0.1)
    received = [0]

    def count(_data) -> None:
        received[0] += 1

    node.create_subscription(message_class(topic_types(node)[topic][0]), topic, count,
                             adapted_qos(node, topic), raw=True)
    print("subscribed", flush=True)
    while not stop.is_set():
        executor.spin_once(timeout_sec=0.2)
    print(received[0], flush=True)


class Subscriber:
    """A process of this file subscribed to a topic (``--watch`` or ``--subscribe``)."""

    def __init__(self, *args: str):
        self.process = subprocess.Popen([sys.executable, __file__, *args], env=child_env(),
                                        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
        if self.process.stdout.readline().strip() != "subscribed":
            raise RuntimeError(f"{args}: did not subscribe (exit {self.process.wait()})")

    def stop(self) -> int:
        """Stop it; the number of messages it received."""
        self.process.terminate()
        out, _ = self.process.communicate(timeout=60)
        return int(out.split()[-1])

    def kill(self) -> None:
        self.process.kill()
        self.process.wait()


class View:
    """`cdpr view` in a process of its own, and optionally one client of it."""

    def __init__(self):
        self.port = free_port()
        self.process = subprocess.Popen(
            [sys.executable, "-m", "cdpr_tools.cli", "view", "--port", str(self.port)], env=child_env(),
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        for line in self.process.stderr:   # until the server listens (its log line)
            if "Foxglove WebSocket server on" in line:
                break
        else:
            raise RuntimeError(f"cdpr view exited with {self.process.wait()} before it listened")
        threading.Thread(target=self.process.stderr.read, daemon=True).start()   # drain the log
        self.client: Subscriber | None = None

    def wait_idle(self, timeout: float = 120.0) -> float:
        """Until the view's start is over (imports, discovering the graph, a channel per topic, a
        client per service: seconds of CPU on a busy machine) - its process used less than
        IDLE_CPU of a core for two seconds in a row; the wall time that took."""
        from bench_graph import process_cpu_s

        t0 = time.monotonic()
        quiet, cpu = 0, process_cpu_s(self.process.pid)
        while quiet < 2 and time.monotonic() - t0 < timeout:
            time.sleep(1.0)
            now = process_cpu_s(self.process.pid)
            quiet = quiet + 1 if now - cpu < IDLE_CPU else 0
            cpu = now
        return time.monotonic() - t0

    def connect(self, topic: str) -> None:
        self.client = Subscriber("--watch", str(self.port), topic)

    def disconnect(self) -> int:
        """Stop the client; the number of messages it received."""
        received, self.client = self.client.stop(), None
        return received

    def close(self) -> None:
        if self.client is not None:
            self.client.kill()
        self.process.send_signal(signal.SIGINT)
        try:
            self.process.wait(30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


class Counts:
    """In this process (the graph's): DDS copies handed to local subscriptions, and thread CPU time in
    ``IntraProcessPublisher.to_dds`` (every publication over DDS). Installed before the graph is built
    (``from_dds`` is bound when a subscription is created)."""

    def __init__(self):
        from cdpr_control.ros.intraprocess import IntraProcessPublisher, LocalSubscription

        self.copies = self.publish_ns = 0
        from_dds, publish = LocalSubscription.from_dds, IntraProcessPublisher.to_dds

        def counted_from_dds(local, msg):
            self.copies += 1
            return from_dds(local, msg)

        def timed_publish(publisher, msg, data=None):
            t0 = time.thread_time_ns()
            try:
                return publish(publisher, msg, data)
            finally:
                self.publish_ns += time.thread_time_ns() - t0
        LocalSubscription.from_dds, IntraProcessPublisher.to_dds = counted_from_dds, timed_publish

    def snapshot(self) -> tuple[int, int]:
        return self.copies, self.publish_ns


def window(probe, seconds: float, counts: Counts) -> dict:
    """RTF, this process's CPU and the counts per simulated period over ``seconds`` of wall time."""
    from bench_graph import PERIOD_S

    cpu0, (wall0, sim0), (copies0, ns0) = time.process_time(), probe.latest, counts.snapshot()
    time.sleep(seconds)
    cpu1, (wall1, sim1), (copies1, ns1) = time.process_time(), probe.latest, counts.snapshot()
    periods = round((sim1 - sim0) * 1e-9 / PERIOD_S)
    return {"rtf": periods * PERIOD_S / (wall1 - wall0), "periods": periods,
            "graph_cpu_us_per_period": (cpu1 - cpu0) * 1e6 / periods if periods else None,
            "dds_copies_per_period": (copies1 - copies0) / periods if periods else None,
            "dds_publish_us_per_period": (ns1 - ns0) * 1e-3 / periods if periods else None,
            "loadavg_1min": os.getloadavg()[0]}


def run(rounds: int) -> list[dict]:
    """The windows in measuring order, each with its ``config`` and ``round``."""
    from bench_graph import ROBOT, START_TIMEOUT_S, ClockProbe, sim_node
    from cdpr_tools.launch import Launcher
    from cdpr_tools.launch_file import load_launch_file
    from cdpr_tools.share import package_share

    description = load_launch_file(package_share("cdpr_tools") / "graphs" / "closed_loop.yaml", {"robot": ROBOT})
    probe = ClockProbe(clock=False)
    counts = Counts()
    windows = []
    view = subscriber = None

    def measure(config: str, k: int, **extra) -> None:
        windows.append({"config": config, "round": k, **window(probe, WINDOW_S, counts), **extra})
        print(json.dumps(windows[-1]), flush=True)

    try:
        with Launcher(description, mode="composed") as launch:
            probe.sim = sim_node(launch)
            probe.wait_running(START_TIMEOUT_S)
            time.sleep(WARMUP_S)
            while probe.latest[1] < WARMUP_SIM_S * 1e9:
                time.sleep(0.1)
            measure("without", 0)
            for k in range(rounds):
                view = View()
                start_s = view.wait_idle()
                time.sleep(SETTLE_S)
                measure("unwatched", k, view_start_s=start_s)
                view.connect(TOPIC)
                steps0 = probe.sim.sim.steps
                time.sleep(SETTLE_S)
                measure("cable_forces", k)
                periods = probe.sim.sim.steps - steps0
                received = view.disconnect()
                windows[-1]["cable_forces_received_per_period"] = received / max(1, periods)
                time.sleep(SETTLE_S)
                measure("unwatched", k)
                view.close()
                view = None
                time.sleep(SETTLE_S)
                measure("without", k)
                subscriber = Subscriber("--subscribe", TOPIC)
                steps0 = probe.sim.sim.steps
                time.sleep(SETTLE_S)
                measure("dds_cable_forces", k)
                periods = probe.sim.sim.steps - steps0
                received, subscriber = subscriber.stop(), None
                windows[-1]["cable_forces_received_per_period"] = received / max(1, periods)
                time.sleep(SETTLE_S)
                measure("without", k + 1)
            errors = list(launch.errors)
    finally:
        if view is not None:
            view.close()
        if subscriber is not None:
            subscriber.kill()
        probe.close()
    if errors:
        raise RuntimeError(f"the graph reported errors: {errors}")
    return windows


def summarize(windows: list[dict], rounds: int) -> dict:
    """Per round each configuration's figures over the mean of the ``without`` windows that begin,
    split and end the round; medians over the rounds."""
    ratios = {c: {"rtf": [], "graph_cpu_us_per_period": []} for c in CONFIGS[1:]}
    for k in range(rounds):
        base = [w for w in windows if w["config"] == "without" and w["round"] in (k, k + 1)]
        for config, figures in ratios.items():
            mine = [w for w in windows if w["config"] == config and w["round"] == k]
            for figure, values in figures.items():
                if all(w[figure] for w in base + mine):
                    values.append(statistics.mean(w[figure] for w in mine) / statistics.mean(w[figure] for w in base))
    med = {c: {f: statistics.median(v) if v else None for f, v in figures.items()} for c, figures in ratios.items()}
    return {
        "unwatched_rtf_ratio": med["unwatched"]["rtf"],
        "one_topic_rtf_ratio": med["cable_forces"]["rtf"],
        "unwatched_cpu_per_period_ratio": med["unwatched"]["graph_cpu_us_per_period"],
        "one_topic_cpu_per_period_ratio": med["cable_forces"]["graph_cpu_us_per_period"],
        "ratios_per_round": ratios,
        "dds_subscriber_rtf_ratio": med["dds_cable_forces"]["rtf"],
        "dds_subscriber_cpu_per_period_ratio": med["dds_cable_forces"]["graph_cpu_us_per_period"],
        "rtf_median": {c: statistics.median(w["rtf"] for w in windows if w["config"] == c) for c in CONFIGS},
        **{f"{figure}_median": {
            c: statistics.median(w[figure] for w in windows if w["config"] == c and w[figure] is not None)
            for c in CONFIGS} for figure in ("graph_cpu_us_per_period", "dds_copies_per_period",
                                              "dds_publish_us_per_period")},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=ROUNDS)
    parser.add_argument("--watch", nargs=2, metavar=("PORT", "TOPIC"), help=argparse.SUPPRESS)
    parser.add_argument("--subscribe", metavar="TOPIC", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.watch:
        watch(int(args.watch[0]), args.watch[1])
        return
    if args.subscribe:
        subscribe(args.subscribe)
        return
    from bench_graph import ROBOT

    windows = run(args.rounds)
    summary = summarize(windows, args.rounds)
    result = {
        "robot": ROBOT, "mode": "composed, lockstep, holding home", "topic_watched": TOPIC,
        "plant": "winch_platform_sim as graphs/closed_loop.yaml configures it (default mismatched plant)",
        "window_s": WINDOW_S, "settle_s": SETTLE_S, "rounds": args.rounds, **summary,
        "targets": TARGETS, "windows": windows, "machine": platform.platform(),
    }
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: v for k, v in summary.items() if k != "ratios_per_round"}, indent=2))


if __name__ == "__main__":
    main()

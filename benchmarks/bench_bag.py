"""Bag benchmark: what recording one 1 kHz control cycle costs, against plain rclpy serialization.

The message set is one cycle of the control graph (docs/architecture): joint states of 8 winches,
cable forces, the force distribution, the set-point, the pose and wrench estimates, two controller
states, FK diagnostics and /clock (10 messages). Measured in the same run:

- baseline: ``rclpy.serialization.serialize_message`` of each message;
- ``bag.encode``: the generated encoder of each message's type (what the composed recorder runs);
- ``BagWriter.write(msg)``: encode, write to MCAP (the in-process path);
- ``BagWriter.write(cdr)``: cut and write already serialized data;
- ``BagWriter.write_serialized``: write encoded data of declared topics (what the writer child does);
- the composed recorder: the set published by an ``IntraProcessNode`` with a ``BagRecorder`` in
  the same context, as a composed graph runs it: CPU time of the publishing (loop) thread per
  message above publishing without the recorder, and of the writer child process;
- the live recorder: the set published at 1 kHz for a few seconds through DDS, recorded by a
  ``BagRecorder`` on an EventsExecutor; messages recorded and the recorder thread's CPU time.

Writes bench/bag.json. Run: .venv/bin/python benchmarks/bench_bag.py
"""
from __future__ import annotations

import gc
import json
import os
import platform
import resource
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message

from cdpr_msgs.msg import (
    CableForces,
    ControllerState,
    ForceDistribution,
    ForwardKinematicsDiagnostics,
    OperationalSetpoint,
)
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from cdpr_tools.bag import BagWriter
from cdpr_tools.bag.encode import encoder
from cdpr_tools.bag.recorder import BagRecorder
from cdpr_control.ros.intraprocess import IntraProcessNode
from cdpr_tools.message_convert import type_name_of
from cdpr_control.ros.runner import spin
from cdpr_tools.ros_graph import new_context

ROOT = Path(__file__).resolve().parents[1]
CYCLES = 2000  # per timing repeat of the in-process paths
REPEATS = 5
LIVE_SECONDS = 3.0
COMPOSED_CYCLES = 5000
RATE_HZ = 1000.0
M, N = 8, 6  # cables, degrees of freedom


def cycle_messages(k: int) -> list[tuple[str, object]]:
    """One control cycle's messages (topic, message), values varying with k."""
    f = [100.0 + k % 50 + i for i in range(M)]
    cables = [f"cable_{i + 1}" for i in range(M)]
    axes = ["x", "y", "z", "a", "b", "c"]
    joints = JointState(name=cables, position=[0.01 * k + i for i in range(M)], velocity=[0.1] * M, effort=f)
    stamp = joints.header.stamp
    stamp.sec, stamp.nanosec = divmod(k * 1_000_000, 1_000_000_000)
    return [
        ("/joint_states", joints),
        ("/cable_forces", CableForces(header=joints.header, f=f, f_min=[10.0] * M, f_max=[3000.0] * M)),
        ("/force_distribution", ForceDistribution(header=joints.header, f_d=f, f_ref=f, f_min=[10.0] * M,
                                                  f_max=[3000.0] * M, method="qp", iterations=4)),
        ("/setpoint", OperationalSetpoint(header=joints.header, line=12)),
        ("/pose", PoseStamped(header=joints.header)),
        ("/wrench", WrenchStamped(header=joints.header)),
        ("/ospc/state", ControllerState(header=joints.header, controller="ospc", enabled=True, names=axes,
                                        reference=[0.1] * N, feedback=[0.1] * N, error=[0.0] * N,
                                        integrator=[0.0] * N, feedforward=[0.0] * N, output=[0.0] * N,
                                        saturated=[False] * N)),
        ("/cfc/state", ControllerState(header=joints.header, controller="cable_force_controller", enabled=True,
                                       names=cables, reference=f, feedback=f, error=[0.0] * M,
                                       integrator=[0.0] * M, feedforward=[0.0] * M, output=[0.0] * M,
                                       saturated=[False] * M)),
        ("/fk/diagnostics", ForwardKinematicsDiagnostics(header=joints.header, formulation="elastic",
                                                         converged=True, iterations=2)),
        ("/clock", Clock(clock=stamp)),
    ]


def per_message_us(fn, messages_per_call: int) -> list[float]:
    """Wall time per message [us] of fn(), one value per repeat (garbage collector paused)."""
    out = []
    for _ in range(REPEATS):
        gc.collect()
        gc.disable()
        try:
            t0 = time.perf_counter_ns()
            fn()
            out.append((time.perf_counter_ns() - t0) / 1e3 / messages_per_call)
        finally:
            gc.enable()
    return out


def summary(values: list[float]) -> dict:
    median = float(np.median(values))
    return {"median_us_per_message": round(median, 3), "min_us_per_message": round(min(values), 3),
            "messages_per_s": round(1e6 / median)}


def in_process(tmp: Path) -> dict:
    cycles = [cycle_messages(k) for k in range(CYCLES)]
    flat = [(t, m) for cycle in cycles for t, m in cycle]
    serialized = [(t, type_name_of(m), serialize_message(m)) for t, m in flat]
    runs = iter(range(10**6))

    def baseline():
        for _, m in flat:
            serialize_message(m)

    encoders = [(encoder(type_name_of(m)), m) for _, m in flat]

    def encode():
        for encode_one, m in encoders:
            encode_one(m)

    def write_messages():
        with BagWriter(tmp / f"msg{next(runs)}") as bag:
            for i, (t, m) in enumerate(flat):
                bag.write(t, None, m, i * 100_000)

    def write_cdr():
        with BagWriter(tmp / f"cdr{next(runs)}") as bag:
            for i, (t, name, data) in enumerate(serialized):
                bag.write(t, name, data, i * 100_000)

    encoded = [(t, encode_one(m), name) for (t, name, _), (encode_one, m) in zip(serialized, encoders)]

    def write_serialized():
        with BagWriter(tmp / f"ser{next(runs)}") as bag:
            for t, _, name in encoded[:len(cycles[0])]:
                bag.add_topic(t, name)
            bag.write_serialized((t, i * 100_000, data, True) for i, (t, data, _) in enumerate(encoded))

    results = {
        "baseline_serialize_message": summary(per_message_us(baseline, len(flat))),
        "bag_encode": summary(per_message_us(encode, len(flat))),
        "bag_writer_write_message": summary(per_message_us(write_messages, len(flat))),
        "bag_writer_write_cdr": summary(per_message_us(write_cdr, len(flat))),
        "bag_writer_write_serialized": summary(per_message_us(write_serialized, len(flat))),
    }
    base = results["baseline_serialize_message"]["median_us_per_message"]
    for key in ("bag_encode", "bag_writer_write_message", "bag_writer_write_cdr", "bag_writer_write_serialized"):
        results[key]["ratio_to_baseline"] = round(results[key]["median_us_per_message"] / base, 2)
    results["bytes_per_cycle"] = sum(len(d) for _, _, d in serialized[:len(cycles[0])])
    return results


def composed_recorder(tmp: Path) -> dict:
    """The set published in-process to a BagRecorder of the same context (a composed graph): CPU
    time per message of the publishing thread, without and with the recorder, and of the writer child."""
    context = new_context()
    try:
        node = IntraProcessNode("bench_bag_publisher", context=context)
        first = cycle_messages(0)
        publishers = {t: node.create_publisher(type(m), t, 1000) for t, m in first}
        cycles = [[(publishers[t], m) for t, m in cycle_messages(k)] for k in range(COMPOSED_CYCLES)]
        count = COMPOSED_CYCLES * len(first)

        def publish_all():
            for cycle in cycles:
                for publisher, msg in cycle:
                    publisher.publish(msg)

        def thread_us_per_message() -> list[float]:
            out = []
            for _ in range(REPEATS):
                t0 = time.thread_time_ns()
                publish_all()
                out.append((time.thread_time_ns() - t0) / 1e3 / count)
            return out

        plain = thread_us_per_message()
        recorder = BagRecorder(context=context, parameter_overrides=[
            Parameter("output", value=str(tmp / "composed")), Parameter("topics", value=[t for t, _ in first])])
        deadline = time.monotonic() + 30
        while len(recorder.recorded_topics) < len(first):
            if time.monotonic() > deadline:
                raise RuntimeError("recorder did not subscribe to every topic within 30 s")
            recorder.selection.discover()
            time.sleep(0.01)
        children0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        recording = thread_us_per_message()
        recorded = recorder.writer.message_count
        recorder.destroy_node()                     # waits for the writer child: its CPU time is in
        children1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        node.destroy_node()
        child_s = (children1.ru_utime + children1.ru_stime) - (children0.ru_utime + children0.ru_stime)
        return {"messages_per_repeat": count, "recorded_messages": recorded,
                "loop_thread_us_per_message_plain": round(float(np.median(plain)), 3),
                "loop_thread_us_per_message_recording": round(float(np.median(recording)), 3),
                "recording_us_per_message_on_loop_thread": round(float(np.median(recording) - np.median(plain)), 3),
                "writer_process_us_per_message": round(child_s * 1e6 / recorded, 3)}
    finally:
        context.try_shutdown()


def live_recorder(tmp: Path) -> dict:
    """The set at 1 kHz through DDS into a BagRecorder; counts and recorder CPU time."""
    pub_context, rec_context = new_context(), new_context()
    try:
        node = Node("bench_bag_publisher", context=pub_context)
        first = cycle_messages(0)
        publishers = {t: node.create_publisher(type(m), t, 1000) for t, m in first}
        recorder = BagRecorder(context=rec_context, parameter_overrides=[
            Parameter("output", value=str(tmp / "live")), Parameter("topics", value=[t for t, _ in first])])
        executor = EventsExecutor(context=rec_context)
        executor.add_node(recorder)
        stop = threading.Event()
        thread = threading.Thread(target=spin, args=(executor, stop), daemon=True)
        thread.start()
        deadline = time.monotonic() + 30
        while (len(recorder.recorded_topics) < len(first)
               or any(p.get_subscription_count() == 0 for p in publishers.values())):
            if time.monotonic() > deadline:
                raise RuntimeError("recorder did not subscribe to every topic within 30 s")
            time.sleep(0.05)
        clock = time.pthread_getcpuclockid(thread.ident)
        cycles = [cycle_messages(k) for k in range(int(LIVE_SECONDS * RATE_HZ))]
        cpu0, count0, t0 = time.clock_gettime(clock), recorder.writer.message_count, time.monotonic()
        for k, cycle in enumerate(cycles):  # paced at 1 kHz; behind schedule it catches up in bursts
            while time.monotonic() < t0 + k / RATE_HZ:
                time.sleep(0.0002)
            for topic, msg in cycle:
                publishers[topic].publish(msg)
        published = len(cycles) * len(first)
        wait_end = time.monotonic() + 10
        while recorder.writer.message_count - count0 < published and time.monotonic() < wait_end:
            time.sleep(0.05)
        elapsed = time.monotonic() - t0
        recorded = recorder.writer.message_count - count0
        cpu = time.clock_gettime(clock) - cpu0
        stop.set()
        thread.join(5)
        recorder.destroy_node()
        node.destroy_node()
        return {"published_messages": published, "recorded_messages": recorded,
                "recorded_fraction": round(recorded / published, 4),
                "recorder_cpu_us_per_message": round(cpu * 1e6 / max(recorded, 1), 2),
                "recorder_cpu_share_of_one_core": round(cpu / elapsed, 3),
                "offered_messages_per_s": round(len(first) * RATE_HZ),
                "duration_s": round(elapsed, 3)}
    finally:
        pub_context.try_shutdown()
        rec_context.try_shutdown()


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="bench_bag_") as tmp:
        tmp = Path(tmp)
        results = {
            "machine": {"python": platform.python_version(), "cpu_count": os.cpu_count(),
                        "load_average_1min": round(os.getloadavg()[0], 2)},
            "message_set": [type_name_of(m) for _, m in cycle_messages(0)],
            "messages_per_cycle": len(cycle_messages(0)),
            "in_process": in_process(tmp),
            "composed_recorder": composed_recorder(tmp),
            "live_recorder_1khz": live_recorder(tmp),
        }
    out = ROOT / "bench" / "bag.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()

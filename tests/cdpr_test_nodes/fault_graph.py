"""Fault injection on a running closed-loop graph (graphs/closed_loop.yaml, IPAnema 3 Mini, lockstep):
a probe in a context of its own publishes bad messages and records /winch/command, /diagnostics
and /program_status; the checks every fault test makes on what it recorded."""
from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import numpy as np
from cdpr_msgs.msg import CableForces, ProgramStatus
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState

from cdpr_control.model.robot import load_robot
from cdpr_tools.demo_cmd import GRAPH
from cdpr_tools.launch import Launcher, select_nodes
from cdpr_tools.launch_file import load_launch_file
from cdpr_tools.program_client import run_program

from .graph import STOPPING, Collector, Spinner, wait_for

ROBOT = "ipanema3_mini"
PERIOD_NS = 1_000_000
TOPICS = {"/winch/command": JointState, "/diagnostics": DiagnosticArray, "/program_status": ProgramStatus,
          "/ground_truth/cable_forces": CableForces}
FORCE_BAND = (0.5, 1.5)     # x f_min, x f_max: the simulated cable forces a fault may not leave ...
EXCURSION_S = 0.1           # ... for longer than this (simulated time) (issue 28)
LOOP_GAP_S = 1.0            # simulated time a fault may keep the loop from commanding (issue 28)
HANG_S = 120.0              # wall-clock guard against a hang, never a margin
MS = 1_000_000              # ns


def excursions(stamps: np.ndarray, f: np.ndarray, cable) -> list[tuple[int, int]]:
    """(first, last) stamps [ns] of the stretches in which some force of f (n, m) at ``stamps`` (n,)
    (sorted) is out of [0.5 f_min, 1.5 f_max] for longer than 100 ms; a stretch still running at
    the end counts to the last stamp."""
    low, high = FORCE_BAND
    out = np.any((f < low * cable.f_min) | (f > high * cable.f_max), axis=1)
    found, started = [], None
    for t, bad, last in zip(stamps, out, [*stamps[1:], None]):
        if bad and started is None:
            started = t
        if started is not None and (not bad or last is None):
            end = t if bad else previous
            if end - started > EXCURSION_S * 1e9:
                found.append((int(started), int(end)))
            started = None
        previous = t
    return found


def longest_excursion(stamps: np.ndarray, f: np.ndarray, cable) -> int:
    """The longest stretch [ns] (first to last stamp) in which some force of f (n, m) at ``stamps``
    (n,) (sorted) is out of [0.5 f_min, 1.5 f_max], of any length (0: none); for the figures the
    fault tests print, :func:`excursions` is the check."""
    low, high = FORCE_BAND
    out = np.any((f < low * cable.f_min) | (f > high * cable.f_max), axis=1)
    longest, started = 0, None
    for t, bad in zip(stamps, out):
        if not bad:
            started = None
            continue
        started = t if started is None else started
        longest = max(longest, int(t - started))
    return longest


class Recording:
    """What a FaultGraph recorded (``collector.messages(topic)``) and the checks on it; a frozen copy
    (:meth:`FaultGraph.recording`) outlives its graph."""

    def __init__(self, robot, messages: dict):
        self.robot = robot
        self.collector = SimpleNamespace(messages=lambda topic: list(messages[topic]))

    def commands(self) -> list[tuple[int, np.ndarray]]:
        return [(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, np.asarray(m.position))
                for m in self.collector.messages("/winch/command")]

    def program_states(self, name: str, since_stamp: int = 0) -> list[int]:
        """The /program_status states of program ``name`` from ``since_stamp`` [ns] on."""
        return [m.state for m in self.collector.messages("/program_status") if m.program == name
                and m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec >= since_stamp]

    # -- checks ---------------------------------------------------------------------------------
    def forces(self, since_stamp: int = 0, until_stamp: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The simulated cable forces (the plant's, /ground_truth/cable_forces) by stamp: stamps [ns] (n,), f (n, m)."""
        # by stamp only (the simulator's start state repeats stamp 0); the arrival order within one
        forces = sorted(((stamp, np.asarray(m.f)) for m in self.collector.messages("/ground_truth/cable_forces")
                         if (stamp := m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec) >= since_stamp),
                        key=lambda p: p[0])
        forces = [(t, f) for t, f in forces if until_stamp is None or t <= until_stamp]
        if not forces:
            return np.zeros(0, dtype=np.int64), np.zeros((0, self.robot.m))
        return np.array([t for t, _ in forces]), np.vstack([f for _, f in forces])

    def excursions(self, since_stamp: int = 0, until_stamp: int | None = None) -> list[tuple[int, int]]:
        """(first, last) stamps [ns] of every stretch of periods in which some simulated cable force
        was out of [0.5 f_min, 1.5 f_max] for more than 100 ms (issue 28)."""
        stamps, f = self.forces(since_stamp, until_stamp)
        return excursions(stamps, f, self.robot.cable)

    def check_forces(self, since_stamp: int = 0, until_stamp: int | None = None) -> None:
        """No simulated cable force (the plant's, /ground_truth/cable_forces) out of
        [0.5 f_min, 1.5 f_max] for more than 100 ms of simulated time, and no gap of more than 1 s
        of simulated time between two commands: the loop ran through the fault (from
        ``since_stamp`` to ``until_stamp`` [ns], None: to the newest)."""
        # (unbound calls: tests/faults/test_fault_checks.py checks this on a stand-in of the recordings)
        stamps, f = Recording.forces(self, since_stamp, until_stamp)
        assert len(stamps), "no /ground_truth/cable_forces"
        low, high = FORCE_BAND
        for first, last in excursions(stamps, f, self.robot.cable):
            raise AssertionError(f"a cable force out of [{low} f_min, {high} f_max] from {first * 1e-9:.3f} s "
                                 f"to {last * 1e-9:.3f} s")
        commands = sorted(t for t, _ in self.commands()
                          if t >= since_stamp and (until_stamp is None or t <= until_stamp))
        assert len(commands) > 1 and np.diff(commands).max() <= LOOP_GAP_S * 1e9, \
            f"the loop stopped for {np.diff(commands).max() * 1e-9:.3f} s of simulated time"

    def check_commands(self, since_stamp: int = 0) -> None:
        """No NaN and no step: every command finite, consecutive ones (by stamp) at most v_max per
        period apart per cable (the joint command's rate limit, which a hold keeps too)."""
        # by stamp, in arrival order within one (a hold and then the period's own command may share it)
        commands = sorted(((t, q) for t, q in self.commands() if t >= since_stamp), key=lambda c: c[0])
        assert commands, "no winch/command"
        stamps = np.array([t for t, _ in commands])
        q = np.vstack([q for _, q in commands])
        assert q.shape[1] == self.robot.m and np.all(np.isfinite(q)), "a command is not finite"
        periods = np.maximum(np.diff(stamps) / PERIOD_NS, 1.0)
        steps = np.abs(np.diff(q, axis=0)).max(axis=1) / periods
        v_step = self.robot.drive.v_max * PERIOD_NS * 1e-9
        assert np.all(steps <= v_step * (1 + 1e-9) + 1e-12), f"a command steps {steps.max():.4g} m > {v_step:.4g} m"


class FaultGraph(Recording):
    """The closed loop without its visualisation, started in ``mode``, and a probe beside it."""

    def __init__(self, mode: str, lockstep_timeout: float, state_timeout: float, input_deadline: int = 50,
                 sync_mode: str = "exact", realtime_factor: float = 1.0):
        """``lockstep_timeout`` [s]: wall time a dead node costs the lockstep loop per period (the
        simulator then advances without a command); ``state_timeout`` [s]: the interpreter fails its
        program after this long without a winch state; ``input_deadline`` [periods]: every node's;
        ``realtime_factor``: free-running, the simulator's pace (below 1 where this machine cannot
        compute the graph's period in real time, which the stale-input check would rightly call a fault)."""
        description = select_nodes(load_launch_file(GRAPH, {"robot": ROBOT, "sync_mode": sync_mode}),
                                   exclude=["visualization"])
        description.parameters["input_deadline"] = input_deadline
        extra = {"winch_platform_sim": {"lockstep_timeout": lockstep_timeout, "realtime_factor": realtime_factor},
                 "gcode_interpreter": {"state_timeout": state_timeout}}
        for spec in description.nodes:
            if spec.label in extra:
                spec.parameters = list(spec.parameters) + [extra[spec.label]]
        self.robot = load_robot(ROBOT)
        self.spinner = Spinner()
        self.collector = self.spinner.add(Collector, topics=TOPICS, qos=QoSProfile(depth=10000))
        self.probe = self.spinner.add(Node, node_name="fault_probe")
        self.publishers: dict = {}
        self.launcher = Launcher(description, mode=mode, stop_timeout=STOPPING)
        try:
            self.launcher.start()
            self.wait_running()
        except BaseException:
            self.close()            # (a graph that does not start is stopped too: no fixture will)
            raise

    def close(self) -> None:
        try:
            self.launcher.stop()
        finally:
            self.spinner.close()

    def recording(self) -> Recording:
        """A copy of everything recorded so far (the checks run on it after the graph has stopped)."""
        return Recording(self.robot, {topic: self.collector.messages(topic) for topic in TOPICS})

    def node(self, name: str):
        """A node of the graph by name (composed: the object in this process)."""
        return next(n for n in self.launcher.nodes if n.get_name() == name)

    # -- observing ------------------------------------------------------------------------------
    def wait_running(self, periods: int = 50, timeout: float = 60.0) -> None:
        """Until the loop has run ``periods`` more periods (commands with new stamps)."""
        start = self.newest_command()
        wait_for(lambda: self.newest_command() >= start + periods * PERIOD_NS, timeout=timeout,
                 what=f"{periods} periods of the loop")

    def newest_command(self) -> int:
        messages = self.collector.messages("/winch/command")
        return max((m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in messages), default=-1)

    def statuses(self, since: int = 0) -> list:
        """Every DiagnosticStatus received (after the first ``since`` arrays)."""
        return [s for a in self.collector.messages("/diagnostics")[since:] for s in a.status]

    def diagnosed(self, *words: str, since: int = 0) -> list:
        """Statuses whose message contains every word."""
        return [s for s in self.statuses(since) if all(w in s.message for w in words)]

    def wait_diagnosed(self, *words: str, since: int = 0, timeout: float = 20.0) -> list:
        wait_for(lambda: self.diagnosed(*words, since=since), timeout=timeout,
                 what=f"/diagnostics naming {words}")
        return self.diagnosed(*words, since=since)

    def mark(self) -> int:
        return self.collector.count("/diagnostics")

    # -- acting ---------------------------------------------------------------------------------
    def publisher(self, msg_type, topic: str):
        """The probe's publisher of ``topic`` (one per topic for the module: a test's publisher must
        not stay behind as one more writer for the next test), once a subscriber has matched it."""
        publisher = self.publishers.get(topic)
        if publisher is None:
            publisher = self.publishers[topic] = self.probe.create_publisher(msg_type, topic, 10)
        wait_for(lambda: publisher.get_subscription_count() > 0, what=f"a subscriber of {topic}")
        return publisher

    def publish(self, msg_type, topic: str, msg, count: int = 1) -> None:
        publisher = self.publisher(msg_type, topic)
        for _ in range(count):
            publisher.publish(msg)
            time.sleep(0.01)

    def start_program(self, text: str, name: str) -> dict:
        """Run ``text`` in a thread; the returned dict gets ``result`` (or ``error``) when it ends."""
        out: dict = {}

        def run():
            try:
                out["result"] = run_program(text, name, timeout=120.0)
            except Exception as exc:        # noqa: BLE001 - reported by the test
                out["error"] = exc
        out["thread"] = threading.Thread(target=run, daemon=True)
        out["thread"].start()
        return out

    def wait_program_state(self, state: int, timeout: float = 30.0) -> None:
        wait_for(lambda: any(m.state == state for m in self.collector.messages("/program_status")[-3:]),
                 timeout=timeout, what=f"program state {state}")

    def push(self, force_x: float, duration: float) -> int:
        """A rectangular pulse of ``force_x`` [N] along x for ``duration`` [s] at the platform's
        origin, through the simulator's ``sim/apply_wrench`` service (the hand's way); -> the stamp
        [ns] of its first simulated period (composed graphs only: read from the simulator)."""
        from cdpr_msgs.srv import ApplyWrench
        from geometry_msgs.msg import Vector3, Wrench

        client = self.probe.create_client(ApplyWrench, "/sim/apply_wrench")
        try:
            assert client.wait_for_service(timeout_sec=30.0), "no /sim/apply_wrench"
            request = ApplyWrench.Request(wrench=Wrench(force=Vector3(x=float(force_x))),
                                          shape=ApplyWrench.Request.SHAPE_RECTANGLE, duration=float(duration))
            future = client.call_async(request)
            wait_for(future.done, timeout=120.0, what="the sim/apply_wrench answer")
            assert future.result().success, future.result().message
        finally:
            self.probe.destroy_client(client)
        pulse = self.node("winch_platform_sim").sim._pulse
        assert pulse is not None and pulse.wrench[0] == force_x
        return int(round(pulse.t_start * 1e9))

    def wait_stamp(self, stamp: int, timeout: float = 120.0) -> None:
        """Until the loop has commanded the period ``stamp`` [ns] (simulated time)."""
        wait_for(lambda: self.newest_command() >= stamp, timeout=timeout,
                 what=f"the loop to reach {stamp * 1e-9:.3f} s of simulated time")


def program_ended(running) -> object:
    running["thread"].join(HANG_S)
    assert "result" in running, running.get("error", "the program did not end")
    return running["result"]


def check_not_done(recording, result, name: str, since: int) -> None:
    """Program ``name`` failed naming the force watch; /program_status says FAILED, never SUCCEEDED."""
    assert not result.success and "force watch" in result.message, result.message
    states = recording.program_states(name, since)
    assert ProgramStatus.FAILED in states and ProgramStatus.SUCCEEDED not in states, states

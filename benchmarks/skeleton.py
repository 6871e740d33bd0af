"""The transport floor: graphs/closed_loop.yaml with nodes that compute nothing.

What the transport and the node layer alone cost per control period: the same nodes (names),
topics, message types, QoS, messages per period and lockstep dependencies as the real graph, on
the same node layer (:class:`~cdpr_control.ros.base.CdprNode`: the callback guard,
:class:`~cdpr_control.ros.sync.StampSync` with its input checks, headers, in-process delivery
or DDS), but every node, once the inputs of a period t_k are complete, only publishes a new
message per per-period publisher: a shallow copy of a real message of that topic with a header
stamped t_k. The skeleton simulator steps (a counter) on the winch command of t_k and publishes
its outputs of t_k + T and /clock, as ``winch_platform_sim`` does; its lockstep watchdog (the
start-up handshake, ``lockstep_timeout``, and no step while in-process deliveries of the period are
still queued) is the real node's method, run on the skeleton's counter.

The topology is derived from the real graph, not written down: :func:`derive` starts the real
graph composed, reads every node's publishers, subscriptions, StampSync instances (their inputs,
primary, required inputs, mode) and timers and services, and counts over a short window how many
messages each publisher sends per simulator step and during which input's delivery (the
publisher's trigger); the result is JSON-able (types by name, one serialized template message per
per-period topic), so that the skeleton also runs one process per node from a spec file
(:func:`description` gives a launch description of :class:`SkeletonNode` nodes for
``cdpr_tools.launch.Launcher``, composed or ``processes``).

Not reproduced: publications that are not per period (/diagnostics, the visualization's markers
on a wall-clock timer, the program status), the interpreter's RunProgram action server, and what
nodes do on stale inputs (``on_stale``, ``StampSync.advance``). The G-code interpreter's lockstep
is its own (not a StampSync): it ticks on winch/state and waits for its set-point source's
(``setpoint_source``) state and set-point of the previous period; that dependency is read from its
``source`` attribute.

Run: python benchmarks/skeleton.py derive SPEC.json   (bench_graph.py measures the skeleton)
"""
from __future__ import annotations

import base64
import importlib
import json
import os
import sys
import time
from collections import Counter
from operator import attrgetter

from rclpy.clock import Clock as RclpyClock, ClockType
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock

from cdpr_control.ros.base import CdprNode
from cdpr_control.ros.intraprocess import IntraProcess
from cdpr_control.ros.lockstep import lockstep_watchdog
from cdpr_control.ros.runner import run_node
from cdpr_control.ros.sync import StampSync, stamp_ns

MODULE = "skeleton"          # this module's name for the launcher (benchmarks/ on sys.path)
SIM = "winch_platform_sim"
PER_PERIOD_MIN = 0.5         # messages per step from which a publisher counts as publishing every period
START_TIMEOUT_S = 180.0


# -- names of types and QoS ---------------------------------------------------------------------
def type_name(cls) -> str:
    """``sensor_msgs/msg/JointState`` of a message or service class."""
    package, kind = cls.__module__.split(".")[:2]
    return f"{package}/{kind}/{cls.__name__}"


def type_of(name: str):
    package, kind, cls = name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), cls)


def qos_dict(qos: QoSProfile) -> dict:
    return {"history": int(qos.history), "depth": int(qos.depth), "reliability": int(qos.reliability),
            "durability": int(qos.durability)}


def qos_of(d: dict) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy(d["history"]), depth=d["depth"],
                      reliability=ReliabilityPolicy(d["reliability"]), durability=DurabilityPolicy(d["durability"]))


def encode(msg) -> str:
    """CDR of a received message, base64; a payload of the type adaptation (ros/adapted.py) as the
    message it stands for."""
    msg = msg.to_msg() if hasattr(msg, "to_msg") else msg
    return base64.b64encode(serialize_message(msg)).decode("ascii")


def decode(data: str, msg_type):
    return deserialize_message(base64.b64decode(data), msg_type)


# -- watching the real graph --------------------------------------------------------------------
class Publications:
    """Counts, per publisher of the given composed nodes, the messages published and the input
    (``(node, topic)`` of the in-process delivery being run, or ``timer``) during which each was
    published; keeps the last message of each. Installed on a running graph (the publishers'
    ``publish`` and the deliveries' callbacks are looked up on every call)."""

    def __init__(self, nodes, registry: IntraProcess, keep: bool = True):
        self.counts: Counter = Counter()           # (node, topic) -> messages
        self.triggers: dict = {}                    # (node, topic) -> Counter of triggering input topics
        self.last: dict = {}                        # (node, topic) -> the last message
        self.stamps: dict = {}                      # (node, topic) -> stamps [ns] in order (keep=False: none)
        self.keep = keep
        self.on = False
        self._stack: list = []                      # (node, input topic) of the running callbacks
        for node in nodes:
            name = node.get_name()
            for publisher in node.publishers:
                publisher.publish = self._counted(name, publisher.topic_name, publisher.publish)
            for timer in node.timers:
                timer.callback = self._entered(name, "timer", timer.callback)
        for topic in registry.topics.values():
            for local in topic.subscriptions:
                if local.node in nodes:
                    local.callback = self._entered(local.node.get_name(), topic.name, local.callback)

    def _entered(self, node: str, topic: str, callback):
        stack = self._stack

        def entered(*args):
            stack.append((node, topic))
            try:
                return callback(*args)
            finally:
                stack.pop()
        return entered

    def _counted(self, node: str, topic: str, publish):
        key = (node, topic)
        self.triggers[key] = Counter()

        def counted(msg):
            if self.on:
                self.counts[key] += 1
                self.last[key] = msg
                top = self._stack[-1] if self._stack else None
                self.triggers[key][top[1] if top is not None and top[0] == node else None] += 1
                if self.keep:
                    self.stamps.setdefault(key, []).append(message_stamp(msg))
            return publish(msg)
        return counted


def message_stamp(msg) -> int | None:
    if isinstance(msg, Clock):
        return msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
    return stamp_ns(msg) if hasattr(msg, "header") else None


def _syncs(node) -> list[StampSync]:
    found = []
    for value in vars(node).values():
        for v in (value.values() if isinstance(value, dict) else value if isinstance(value, (list, tuple)) else (value,)):
            if isinstance(v, StampSync) and v not in found:
                found.append(v)
    return found


def derive(robot: str = "ipanema3_mini", window_s: float = 1.0, warmup_s: float = 1.0) -> dict:
    """The skeleton's spec: the real graph (graphs/closed_loop.yaml, lockstep) started composed and
    watched for ``window_s`` after ``warmup_s`` of running."""
    from cdpr_tools.demo_cmd import GRAPH
    from cdpr_tools.launch import Launcher
    from cdpr_tools.launch_file import load_launch_file

    description = load_launch_file(GRAPH, {"robot": robot, "sync_mode": "exact"})
    with Launcher(description, mode="composed") as launch:
        nodes = launch.nodes
        sim = next(n for n in nodes if n.get_name() == SIM)
        deadline = time.monotonic() + START_TIMEOUT_S
        while sim.sim.steps == 0:
            if time.monotonic() > deadline:
                raise TimeoutError("the real graph did not start looping")
            time.sleep(0.05)
        time.sleep(warmup_s)
        registry = IntraProcess.of(nodes[0].context)
        watch = Publications(nodes, registry, keep=False)
        deliveries0, watch.on = registry.deliveries, True
        time.sleep(window_s)
        watch.on = False
        deliveries = registry.deliveries - deliveries0
        spec = _spec(launch, watch, registry)
        if launch.errors:
            raise RuntimeError(f"the real graph reported errors: {launch.errors}")
    steps = watch.counts[(SIM, "/winch/state")]
    spec["window"] = {"steps": steps, "messages_per_period": sum(watch.counts.values()) / steps,
                      "deliveries_per_period": deliveries / steps}
    return spec


def _spec(launch, watch: Publications, registry: IntraProcess) -> dict:
    steps = watch.counts[(SIM, "/winch/state")]
    if steps < 10:
        raise RuntimeError(f"the real graph advanced only {steps} periods in the window")
    urgent = {local.dds: local.urgent for t in registry.topics.values() for local in t.subscriptions}
    nodes = {}
    for node in launch.nodes:
        name = node.get_name()
        syncs = _syncs(node)
        sync_subs = {s for sync in syncs for s in sync.subscriptions}
        sync_timers = {getattr(sync, "timer", None) for sync in syncs}
        use_sim_time = bool(node.get_parameter("use_sim_time").value)
        entry = {
            "parameters": {"robot": node.get_parameter("robot").value, "control_period": node.dt,
                           "sync_mode": node.sync_mode, "input_deadline": node.input_deadline,
                           "use_sim_time": use_sim_time},
            "syncs": [],
            "subscriptions": [],
            "publishers": [],
            "timers": [{"period_ns": t.timer_period_ns, "clock": int(t.clock.clock_type)} for t in node.timers
                       if t not in sync_timers and t is not registry.wake_timer],
            "services": [{"name": s.srv_name, "type": type_name(s.srv_type)} for s in node.services],
        }
        topics = {}
        for i, sync in enumerate(syncs):
            subs = dict(zip(sync.names, sync.subscriptions))
            topics.update({subs[n].topic_name: i for n in sync.names})
            entry["syncs"].append({
                "inputs": {n: [type_name(subs[n].msg_type), subs[n].topic_name] for n in sync.names},
                "primary": sync.primary, "optional": [n for n in sync.names if n not in sync.required],
                "mode": sync.mode, "sizes": dict(sync.sizes), "deadline": sync.deadline,
                "urgent": [n for n in sync.names if urgent.get(subs[n])],
                "qos": qos_dict(subs[sync.primary].qos_profile)})
        for s in node.subscriptions:
            if s in sync_subs or (use_sim_time and s.topic_name == "/clock"):   # (its TimeSource's)
                continue
            entry["subscriptions"].append({"topic": s.topic_name, "type": type_name(s.msg_type),
                                           "qos": qos_dict(s.qos_profile), "urgent": bool(urgent.get(s))})
        # the interpreter's own lockstep: a tick waits for its set-point source's previous period
        source = getattr(node, "source", None) if isinstance(getattr(node, "source_msgs", None), dict) else None
        entry["waits_previous"] = sorted(s["topic"] for s in entry["subscriptions"] if source and any(
            s["topic"].endswith(f"/{source}/{key}") for key in ("state", "setpoint")))
        for p in node.publishers:
            key = (name, p.topic_name)
            count = watch.counts[key]
            per_period = round(count / steps) if count >= PER_PERIOD_MIN * steps else 0
            publisher = {"topic": p.topic_name, "type": type_name(p.msg_type), "qos": qos_dict(p.qos_profile),
                         "per_period": per_period, "published": count}
            if per_period:
                triggers = watch.triggers[key]
                trigger = max((t for t in triggers if t not in entry["waits_previous"]),
                              key=triggers.__getitem__, default=None)
                publisher["trigger"] = ({"sync": topics[trigger]} if trigger in topics else {"topic": trigger})
                publisher["template"] = encode(watch.last[key])
            entry["publishers"].append(publisher)
        if name == SIM:
            entry["lockstep_timeout"] = node.lockstep_timeout
        nodes[name] = entry
    return {"robot": launch.nodes[0].robot.name, "period_ns": int(round(launch.nodes[0].dt * 1e9)),
            "sim": SIM, "nodes": nodes}


def save(spec: dict, path) -> None:
    with open(path, "w") as f:
        json.dump(spec, f, indent=1)


def load(path) -> dict:
    with open(path) as f:
        return json.load(f)


def per_period_topics(spec: dict) -> dict[str, int]:
    """Topic -> messages per period, over every node."""
    counts: Counter = Counter()
    for entry in spec["nodes"].values():
        for p in entry["publishers"]:
            counts[p["topic"]] += p["per_period"]
    return {t: n for t, n in counts.items() if n}


def description(spec_path, spec: dict | None = None):
    """A launch description (cdpr_tools.launch) of the skeleton: one :class:`SkeletonNode` per node."""
    from cdpr_tools.launch import LaunchDescription, NodeSpec

    spec = load(spec_path) if spec is None else spec
    nodes = [NodeSpec(module=MODULE, name=name, parameters=[{**entry["parameters"], "skeleton_spec": str(spec_path)}])
             for name, entry in spec["nodes"].items()]
    sync_mode = next(iter(spec["nodes"].values()))["parameters"]["sync_mode"]
    return LaunchDescription(nodes=nodes, parameters={"sync_mode": sync_mode})


# -- the skeleton -------------------------------------------------------------------------------
def _copier(cls):
    """A shallow copy of a message (what ``copy.copy`` gives, 1.7 us rather than 4.7 for a JointState)."""
    slots = tuple(cls.__slots__)
    get, new, put = attrgetter(*slots), cls.__new__, object.__setattr__

    def copy(template):
        msg = new(cls)
        for slot, value in zip(slots, get(template)):
            put(msg, slot, value)
        return msg
    return copy


class _Steps:
    steps = 0       # what bench_graph reads of the simulator (``sim.sim.steps``)


class SkeletonNode(CdprNode):
    """One node of the skeleton, named by the launcher; its part of the spec file ``skeleton_spec``."""

    def __init__(self, **kwargs):
        super().__init__("skeleton", **kwargs)
        self.declare_parameter("skeleton_spec", "")
        spec = load(self.get_parameter("skeleton_spec").value)
        entry = spec["nodes"][self.get_name()]
        self.period_ns = spec["period_ns"]
        self.latest: dict[str, object] = {}
        own = {p.topic_name for p in self.publishers}                        # /diagnostics, /parameter_events
        on_sync: dict[int, list] = {}
        on_topic: dict[str, list] = {}
        self.outputs = []                                                     # (publisher, template, copy, n)
        self.clock_pub = None
        for p in entry["publishers"]:
            if p["topic"] in own:
                continue
            msg_type = type_of(p["type"])
            publisher = self.create_publisher(msg_type, p["topic"], qos_of(p["qos"]))
            if not p["per_period"]:
                continue
            if msg_type is Clock:
                self.clock_pub = publisher
                continue
            template = decode(p["template"], msg_type)
            out = (publisher, template, _copier(msg_type), p["per_period"], hasattr(template, "header"))
            self.outputs.append(out)
            trigger = p.get("trigger", {})
            if "sync" in trigger:
                on_sync.setdefault(trigger["sync"], []).append(out)
            else:
                on_topic.setdefault(trigger.get("topic"), []).append(out)
        self.syncs = []
        for i, s in enumerate(entry["syncs"]):
            inputs = {name: (type_of(t), topic) for name, (t, topic) in s["inputs"].items()}
            outputs = on_sync.get(i, [])
            self.syncs.append(StampSync(self, inputs, s["primary"], lambda msgs, t, o=outputs: self.publish_period(o, t),
                                        mode=s["mode"], qos=qos_of(s["qos"]), optional=tuple(s["optional"]),
                                        sizes=s["sizes"], deadline=s["deadline"], urgent=tuple(s["urgent"])))
        self.is_sim = self.get_name() == spec["sim"]
        if self.is_sim:
            self._sim_init(entry, on_topic)
        else:
            self._plain_init(entry, on_topic)
        existing = {s.srv_name for s in self.services}                       # the parameter services
        for s in entry["services"]:
            if s["name"] not in existing:
                srv_type = type_of(s["type"])
                self.create_service(srv_type, s["name"], lambda request, response: response)
        # the others' timers, doing nothing (the simulator's shortest is its watchdog, see _sim_init)
        for t in sorted(entry["timers"], key=lambda t: t["period_ns"])[1 if self.is_sim else 0:]:
            self.create_timer(t["period_ns"] * 1e-9, lambda: None, clock=RclpyClock(clock_type=ClockType(t["clock"])))
        if self.is_sim:
            self._publish()

    def publish_period(self, outputs, t: int) -> None:
        """Period ``t`` of ``outputs``: new messages, copies of the templates stamped ``t``."""
        header = None
        for publisher, template, copy, n, stamped in outputs:
            for _ in range(n):
                msg = copy(template)
                if stamped:
                    if header is None or header.frame_id != template.header.frame_id:
                        header = self.header(t, template.header.frame_id)
                    msg.header = header
                publisher.publish(msg)

    def _keep(self, topic: str):
        latest = self.latest

        def keep(msg):
            latest[topic] = msg
        return keep

    # -- a node publishing on a plain input (the G-code interpreter on winch/state) ---------------
    def _plain_init(self, entry: dict, on_topic: dict) -> None:
        self.waits = tuple(entry["waits_previous"])
        self.waiting: int | None = None
        self.last_tick = -1
        self.source: dict[int, set] = {}
        for s in entry["subscriptions"]:
            topic, outputs = s["topic"], on_topic.get(s["topic"])
            if outputs:
                callback = self._trigger(outputs)
            elif topic in self.waits:
                callback = self._source(topic)
            else:
                callback = self._keep(topic)
            self.create_subscription(type_of(s["type"]), topic, callback, qos_of(s["qos"]), urgent=s["urgent"])

    def _trigger(self, outputs):
        def receive(msg):
            t = stamp_ns(msg)
            if t > self.last_tick:
                if self.waits and self.last_tick >= 0 and len(self.source.get(self.last_tick, ())) < len(self.waits):
                    self.waiting = t        # the source's previous period is not there yet
                    return
                self._tick(outputs, t)
            elif t == self.last_tick:       # a repeated start-up state: the period again, for late joiners
                self.publish_period(outputs, t)
        self.tick_outputs = outputs
        return receive

    def _source(self, topic: str):
        def receive(msg):
            self.source.setdefault(stamp_ns(msg), set()).add(topic)
            if self.waiting is not None and len(self.source.get(self.last_tick, ())) == len(self.waits):
                waiting, self.waiting = self.waiting, None
                self._tick(self.tick_outputs, waiting)
        return receive

    def _tick(self, outputs, t: int) -> None:
        previous, self.last_tick = self.last_tick, t
        for old in [s for s in self.source if s < previous]:
            del self.source[old]
        self.publish_period(outputs, t)

    # -- the simulator ----------------------------------------------------------------------------
    def _sim_init(self, entry: dict, on_topic: dict) -> None:
        self.sim = _Steps()
        self.got_command = False
        self.command_stamp = -1
        self.missed_deadlines = 0
        self.lockstep_timeout = entry["lockstep_timeout"]
        self.sim_outputs = [out for outputs in on_topic.values() for out in outputs]
        self._last_handshake = -1e9
        self._waiting_since = time.monotonic()
        for s in entry["subscriptions"]:
            topic = s["topic"]
            callback = self._on_command if on_topic.get(topic) else self._keep(topic)
            self.create_subscription(type_of(s["type"]), topic, callback, qos_of(s["qos"]), urgent=s["urgent"])
        first = min(entry["timers"], key=lambda t: t["period_ns"])    # its lockstep watchdog
        self.create_timer(first["period_ns"] * 1e-9, self._lockstep_watchdog,
                          clock=RclpyClock(clock_type=ClockType(first["clock"])))

    def _on_command(self, msg) -> None:
        stamp, t = stamp_ns(msg), self.sim.steps * self.period_ns
        if stamp > t or stamp < self.command_stamp:
            return
        self.command_stamp, self.got_command = stamp, True
        if stamp == t:
            self._advance()

    def _advance(self) -> None:
        self.sim.steps += 1
        self._waiting_since = time.monotonic()
        self._publish()

    # the real simulator's watchdog (not a copy, and without importing the simulator - pybullet -
    # in each of the skeleton's processes: the one-process-per-node floor then took over 180 s to start)
    _lockstep_watchdog = lockstep_watchdog

    def _publish(self) -> None:
        t = self.sim.steps * self.period_ns
        if self.clock_pub is not None:
            self.clock_pub.publish(Clock(clock=self.header(t).stamp))
        self.publish_period(self.sim_outputs, t)


def main(args=None):
    run_node(SkeletonNode, args)


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import skeleton   # noqa: E402  (the classes under their module name, for the launcher)

    if len(sys.argv) != 3 or sys.argv[1] != "derive":
        sys.exit("usage: skeleton.py derive SPEC.json")
    skeleton.save(skeleton.derive(), sys.argv[2])
    print(json.dumps({t: n for t, n in skeleton.per_period_topics(skeleton.load(sys.argv[2])).items()}, indent=1))

"""Running a node's cycle once per control period on matching inputs.

In lockstep simulation every message of period k carries the stamp t_k (each node copies the
stamp of its inputs), so a node computes period k exactly once, when all its inputs for t_k are
there: the graph is a deterministic data flow. With ``mode="latest"`` (free-running, hardware) the
cycle runs on every message of the primary input with the newest of the others; ``optional``
inputs need not have arrived there (their entry is then missing), in lockstep every input is awaited.

Faults at the input (issue "faults, bad input and crashes"), in both modes:

- a message that is not valid for the robot (:func:`input_problem`: array lengths against the m
  cables or the 6 pose dimensions, non-finite values, a pose or wrench not in the base frame) is
  dropped, counted and reported on /diagnostics naming the topic and the reason;
- a stamp that jumps, more than ``input_deadline`` periods ahead of that input's newest stamp and
  of the node's time (its newest input, its simulated clock), or back behind the input's newest, is
  dropped and reported unless the next message of the input continues from it (a restarted
  publisher; one spoofed far stamp cannot discard every real period); on simulated time a stamp
  more than ``input_deadline`` periods ahead of the node's clock is dropped every time (a stream of
  far-future stamps cannot pass for a restarted publisher and stop the loop);
- in lockstep, a stamp behind the input's newest but of a period not yet run (a foreign publisher a
  few periods ahead of the real one) goes into that period's bucket, so the real stream still
  completes every period;
- a required input whose newest stamp falls more than ``input_deadline`` periods behind the newest
  stamp of the node's other inputs (or the node's clock: simulated time, or :meth:`StampSync.advance`) is *stale*: its
  producer stopped. It is reported once, naming the topic, and listed in :attr:`StampSync.stale`
  (the joint command then holds); reported again when it is fresh.
"""
from __future__ import annotations

from math import isfinite
from typing import Callable

from cdpr_msgs.msg import CableForces, ControllerState, ForceDistribution, OperationalSetpoint
from geometry_msgs.msg import InertiaStamped, PoseStamped, WrenchStamped
from sensor_msgs.msg import JointState

from cdpr_control.control.safety import all_finite

from cdpr_control.ros.adapted import Payload
from cdpr_control.ros.qos import CONTROL

BASE_FRAMES = ("", "base", "world")     # frame_id accepted for poses, wrenches and set-points


def stamp_ns(msg) -> int:
    s = msg._header._stamp      # the slots (this runs for every message of the loop)
    return s._sec * 1_000_000_000 + s._nanosec


def _vector3_sum(v) -> float:
    return v.x + v.y + v.z


def _pose_sum(p) -> float:
    o = p.orientation
    return p.position.x + p.position.y + p.position.z + o.x + o.y + o.z + o.w


def _cables(name: str, values, m: int, required: bool = True) -> str | None:
    if not required and len(values) == 0:
        return None
    if len(values) != m:
        return f"{name} has {len(values)} values, the robot has {m} cables"
    return None if all_finite(values) else f"{name} has non-finite values"


def _frame(msg) -> str | None:
    frame = msg.header.frame_id
    return None if frame in BASE_FRAMES else f"frame_id {frame!r} is not the base frame"


def _pose_problem(name: str, pose) -> str | None:
    if not isfinite(_pose_sum(pose)):
        return f"{name} has non-finite values"
    o = pose.orientation
    if o.x * o.x + o.y * o.y + o.z * o.z + o.w * o.w < 1e-12:
        return f"{name} has a zero quaternion"
    return None


def _joint_state(msg, m):
    return (_cables("position", msg.position, m) or _cables("velocity", msg.velocity, m, False)
            or _cables("effort", msg.effort, m, False))


def _cable_forces(msg, m):
    return _cables("f", msg.f, m) or _cables("f_min", msg.f_min, m, False) or _cables("f_max", msg.f_max, m, False)


def _force_distribution(msg, m):
    return _cables("f_d", msg.f_d, m) or _cables("f_min", msg.f_min, m) or _cables("f_max", msg.f_max, m)


def _controller_state(msg, m):
    n = len(msg.output)
    if n not in (6, m):
        return f"output has {n} values, need 6 (pose) or {m} (cables)"
    return None if all_finite(msg.output) else "output has non-finite values"


def _pose_stamped(msg, m):
    return _frame(msg) or _pose_problem("pose", msg.pose)


def _wrench_stamped(msg, m):
    w = msg.wrench
    return _frame(msg) or (None if isfinite(_vector3_sum(w.force) + _vector3_sum(w.torque))
                           else "wrench has non-finite values")


def _setpoint(msg, m):
    v, a = msg.velocity, msg.acceleration
    rates = (_vector3_sum(v.linear) + _vector3_sum(v.angular) + _vector3_sum(a.linear) + _vector3_sum(a.angular)
             + _vector3_sum(msg.force))
    return (_frame(msg) or _pose_problem("pose", msg.pose)
            or (None if isfinite(rates) else "velocity, acceleration or force has non-finite values"))


def _inertia(msg, m):
    i = msg.inertia
    return None if isfinite(i.m + _vector3_sum(i.com)) else "mass or com has non-finite values"


CHECKS = {JointState: _joint_state, CableForces: _cable_forces, ForceDistribution: _force_distribution,
          ControllerState: _controller_state, PoseStamped: _pose_stamped, WrenchStamped: _wrench_stamped,
          OperationalSetpoint: _setpoint, InertiaStamped: _inertia}


_CHECKED: dict[int, tuple] = {}    # id(msg) -> (msg, m, problem): the messages checked lately
_CHECKED_MAX = 256


def input_problem(msg, m: int, size: int | None = None) -> str | None:
    """Why ``msg`` is no valid input for a robot of ``m`` cables (None: valid). ``size``: the exact
    length of a ControllerState's output (e.g. m for the CFC's Δq, 6 for an offset).

    In a composed graph every subscriber of a topic receives the same message object (published
    messages are not modified, intraprocess.py), so the check of its content runs once per message,
    not once per subscriber (the set-point has nine): the result is kept with the object itself,
    which also keeps its id from being reused while it is remembered."""
    entry = _CHECKED.get(id(msg))
    if entry is not None and entry[0] is msg and entry[1] == m:
        problem = entry[2]
    else:
        check = CHECKS.get(msg.msg_type if isinstance(msg, Payload) else type(msg))
        problem = check(msg, m) if check is not None else None
        if len(_CHECKED) >= _CHECKED_MAX:
            _CHECKED.clear()
        _CHECKED[id(msg)] = (msg, m, problem)
    if problem is None and size is not None and len(msg.output) != size:
        problem = f"output has {len(msg.output)} values, need {size}"
    return problem


class StampJumps:
    """Stamps of input streams: a stamp more than ``limit_ns`` ahead of the stream's newest (and of
    ``reference``, the receiver's time), or behind it, is a jump, refused unless the stream's next
    stamp continues from it (a restarted publisher). Where the receiver has a ``clock`` of its own
    (simulated time from /clock), a stamp more than ``limit_ns`` ahead of that clock is refused
    every time: no publisher can be ahead of time, and a stream of far-future stamps (a clock
    fault, a foreign publisher) repeating the same stamp must not pass for a restarted publisher.
    Likewise a stamp behind its stream's newest and more than ``limit_ns`` behind that clock: a
    second, older stream on the topic, which the restart rule would let take turns with the real
    one (measured: a graph's /cable_forces alternated with another's 265-414 periods older)."""

    def __init__(self, periods: int, limit_ns: int):
        self.periods, self.limit_ns = periods, limit_ns
        self.newest: dict[str, int] = {}
        self.jumped: dict[str, int] = {}

    def check(self, name: str, t: int, reference: Callable[[], int] | None = None,
              clock: Callable[[], int | None] | None = None) -> str | None:
        """None if ``t`` is accepted (and now the newest of ``name``), else the reason it is refused.
        ``reference()``: the receiver's time now [ns] (asked only when ``t`` is ahead of its stream);
        ``clock()``: the receiver's own clock [ns], None while it has none (e.g. before /clock)."""
        last = self.newest.get(name)
        if last is None or last <= t <= last + self.limit_ns \
                or (last < t and reference is not None and t <= reference() + self.limit_ns):
            self.newest[name] = t
            return None
        now = clock() if clock is not None else None
        if now is not None:
            if last < t:
                if t > now + self.limit_ns:
                    return (f"stamp {t * 1e-9:.3f} s is more than {self.periods} periods ahead of the clock "
                            f"{now * 1e-9:.3f} s")
                self.newest[name] = t               # the clock vouches for it
                return None
            if t < now - self.limit_ns:
                # behind the stream and behind the clock: a publisher that restarted would have
                # restarted the clock with it; this is a second stream (a bag played into the
                # graph, another graph on the domain) and must not take turns with the real one
                return (f"stamp {t * 1e-9:.3f} s is more than {self.periods} periods behind the clock "
                        f"{now * 1e-9:.3f} s (older than the last {last * 1e-9:.3f} s)")
        jumped = self.jumped.pop(name, None)
        if jumped is not None and jumped <= t <= jumped + self.limit_ns:
            self.newest[name] = t
            return None
        self.jumped[name] = t
        where = f"more than {self.periods} periods ahead of" if t > last else "older than"
        return f"stamp {t * 1e-9:.3f} s is {where} the last {last * 1e-9:.3f} s"


class StampSync:
    def __init__(self, node, inputs: dict[str, tuple[type, str]], primary: str,
                 callback: Callable[[dict, int], None], mode: str = "exact", qos=CONTROL,
                 optional: tuple[str, ...] = (), sizes: dict[str, int] | None = None,
                 deadline: int | None = None, on_stale: Callable[[int], None] | None = None,
                 urgent: tuple[str, ...] = ()):
        """``urgent``: inputs on the robot's command path, delivered in-process before other queued
        messages (intraprocess.py: a free-running period's command then waits for nothing else)."""
        if primary not in inputs:
            raise ValueError(f"primary input {primary!r} not among {list(inputs)}")
        if primary in optional or not set(optional) <= set(inputs):
            raise ValueError(f"optional inputs {optional} must be non-primary inputs among {list(inputs)}")
        self.node = node
        self.mode = mode
        self.primary = primary
        self.callback = callback
        self.latest: dict[str, object] = {}
        self.pending: dict[int, dict[str, object]] = {}
        self.names = tuple(inputs)
        self.required = tuple(n for n in inputs if n not in optional)
        self.topics = {name: topic for name, (_, topic) in inputs.items()}
        self.m = node.robot.m
        self.sizes = sizes or {}
        period_ns = max(1, int(round(node.dt * 1e9)))
        self.deadline = int(getattr(node, "input_deadline", 50) if deadline is None else deadline)
        self.deadline_ns = self.deadline * period_ns
        self.jumps = StampJumps(self.deadline, self.deadline_ns)
        self.newest = self.jumps.newest      # newest accepted stamp per input
        self.now = -1                        # the newest stamp of any input (or advance())
        self.done = -1                       # lockstep: the stamp of the newest period run
        self.stale: tuple[str, ...] = ()     # required inputs older than the deadline
        # while none is stale: no required input can turn stale before this time [ns] (their
        # newest stamps only grow on the common path), so _check_deadlines has nothing to look at
        # (-1: look; 12 nodes looking at every input each period cost about 10 us of the loop)
        self._calm_until = -1
        self.on_stale = on_stale             # called with t for each new period while an input is stale
        self.sim_time = node.has_parameter("use_sim_time") and bool(node.get_parameter("use_sim_time").value)
        if not set(urgent) <= set(inputs):
            raise ValueError(f"urgent inputs {urgent} must be among {list(inputs)}")
        self.subscriptions = [
            node.create_subscription(msg_type, topic, self._receiver(name), qos, adapted=True,  # reads fields only
                                     **({"urgent": True} if name in urgent else {}))
            for name, (msg_type, topic) in inputs.items()
        ]
        # on simulated time the clock (/clock of the simulator) advances also when every input of
        # this node stopped: look at it twice per deadline (on wall time there is nothing to compare)
        if self.sim_time:
            self.timer = node.create_timer(0.5 * self.deadline_ns * 1e-9, self._watch)

    def _watch(self) -> None:
        self.advance(self.node.get_clock().now().nanoseconds)

    def _reject(self, name: str, reason: str) -> None:
        input_fault = getattr(self.node, "input_fault", None)
        if input_fault is not None:
            input_fault(self.topics[name], reason)

    def reference(self) -> int:
        """The node's time now: its newest input, or its (simulated) clock."""
        return max(self.now, self.node.get_clock().now().nanoseconds) if self.sim_time else self.now

    def clock(self) -> int | None:
        """The node's own clock [ns] where it has one independent of its inputs (simulated time once
        /clock runs), else None."""
        if not self.sim_time:
            return None
        now = self.node.get_clock().now().nanoseconds
        return now if now > 0 else None

    def _accept_stamp(self, name: str, t: int) -> bool:
        self._calm_until = -1               # (a restarted stream's newest stamp may go back)
        reason = self.jumps.check(name, t, self.reference, self.clock)
        if reason is not None:
            self._reject(name, reason)
        return reason is None

    def advance(self, t: int) -> None:
        """The node's clock reached ``t`` (e.g. a winch state the node watches): check the deadlines."""
        if t > self.now:
            self.now = t
            self._check_deadlines(t)

    def _check_deadlines(self, t: int, tick: bool = True) -> None:
        if t <= self._calm_until:
            return                              # none stale, and none can be yet
        newest, limit = self.newest, t - self.deadline_ns
        stale = tuple(n for n in self.required if n in newest and newest[n] < limit)
        if not stale:
            seen = [newest[n] for n in self.required if n in newest]
            self._calm_until = min(seen) + self.deadline_ns if seen else -1
        if stale != self.stale:
            self.stale = stale
            report = getattr(self.node, "report_stale", None)
            if report is not None:
                report({self.topics[n]: (t - newest[n]) / (self.deadline_ns / self.deadline) for n in stale},
                       self.deadline, t)
        if stale and tick and self.on_stale is not None:
            self.on_stale(t)

    def _receiver(self, name: str):
        m, size = self.m, self.sizes.get(name)
        newest, limit_ns, latest, pending = self.jumps.newest, self.jumps.limit_ns, self.latest, self.pending
        n_inputs, lockstep = len(self.names), self.mode != "latest"

        def receive(msg):
            problem = input_problem(msg, m, size)
            if problem is not None:
                self._reject(name, problem)
                return
            t = stamp_ns(msg)
            last = newest.get(name)
            if last is not None and last <= t <= last + limit_ns:
                newest[name] = t                    # the common case of StampJumps.check, inline
            elif lockstep and last is not None and self.done < t < last and t >= last - limit_ns:
                pass    # behind the stream's newest but for a period not yet run: its bucket takes it
                #         (a foreign publisher a few periods ahead must not make the real stream's
                #         messages "older" and leave the lockstep period incomplete)
            elif not self._accept_stamp(name, t):
                return
            if t > self.now:
                self.now = t
                self._check_deadlines(t)
            elif self.stale and name in self.stale:
                self._check_deadlines(self.now, tick=False)
            if t >= newest[name]:
                latest[name] = msg
            if lockstep:
                bucket = pending.get(t)
                if bucket is None:
                    bucket = pending[t] = {}
                bucket[name] = msg
                if len(bucket) == n_inputs:
                    # complete: run this period and forget it and anything older
                    for old in [s for s in pending if s <= t]:
                        del pending[old]
                    self.done = max(self.done, t)
                    self.callback(bucket, t)
                elif len(pending) > 100:            # an input stopped: drop the oldest period
                    del pending[min(pending)]
            elif name == self.primary and all(n in latest for n in self.required):
                self.callback(dict(latest), t)
        return receive

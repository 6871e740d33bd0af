"""Jerk-limited interpolation of G-code programs (thesis sections 2.3.2 and 5.1.2).

The geometric path (gcode_path) is travelled with a time law s(t) from ruckig: each chain of
smoothly joined segments is one ruckig profile from standstill to standstill on u = s/L, so
position, velocity and acceleration are continuous, the jerk is bounded and arcs stay on the arc.
The set-point follows from the chain rule:

    x_d = q(s),  xdot_d = q' s_dot,  xddot_d = q'' s_dot^2 + q' s_ddot,
    jerk = q''' s_dot^3 + 3 q'' s_dot s_ddot + q' s_dddot,

so limits on s_dot, s_ddot, s_dddot are derived from the group limits (translation, rotation,
force) and the bounds of |q'|, |q''|, |q'''| (path_limits). Pause and cancel brake u with
ruckig's velocity interface to standstill; the force axes F_d,0 are interpolated with the motion.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np
from ruckig import (ControlInterface, DurationDiscretization, InputParameter, Result, Ruckig, RuckigError,
    Trajectory)

from cdpr_control.motion.path import Chain, joins_smoothly
from cdpr_control.motion.program import (Diagnostic, Dwell, GCodeError, Motion, ParameterCommand, Program,
    ProgramStop)

#: Share of a_max that the centripetal acceleration on arcs may take; the rest drives s_ddot.
CENTRIPETAL_SHARE = 0.5


@dataclass(frozen=True)
class AxisLimits:
    """Limits on the Euclidean norm of a group's 1st, 2nd and 3rd time derivative."""

    velocity: float
    acceleration: float
    jerk: float

    def __post_init__(self):
        for name in ("velocity", "acceleration", "jerk"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} limit must be finite and positive, got {value!r}")


@dataclass(frozen=True)
class Limits:
    """Interpolation limits: translation in m/s, m/s^2, m/s^3 (norm of xdot[0:3] ...), rotation in
    rad/s ... (norm of the Kardan angle rates), force axes in N/s, N/s^2, N/s^3."""

    translation: AxisLimits = AxisLimits(0.5, 2.0, 20.0)
    rotation: AxisLimits = AxisLimits(1.0, 5.0, 50.0)
    force: AxisLimits = AxisLimits(200.0, 2000.0, 20000.0)

    def groups(self) -> tuple[AxisLimits, AxisLimits, AxisLimits]:
        return self.translation, self.rotation, self.force


class ProgramState(enum.Enum):
    RUNNING = "running"        # moving or dwelling
    PAUSING = "pausing"        # jerk-limited braking after pause()
    PAUSED = "paused"          # standstill after pause() or M0/M1; resume() continues
    WAITING = "waiting"        # waiting for command_done() of a parameter command
    CANCELLING = "cancelling"  # jerk-limited braking after cancel()
    CANCELLED = "cancelled"
    DONE = "done"
    FAILED = "failed"          # a parameter command failed or the program was aborted (Interpolator.error)


TERMINAL_STATES = frozenset({ProgramState.CANCELLED, ProgramState.DONE, ProgramState.FAILED})


@dataclass(frozen=True, eq=False)
class Setpoint:
    """One interpolation cycle: time t (s), pose x, xd, xdd (6: m, rad), desired force F_d,0 (3, N),
    the program line, state, progress in [0, 1] and the parameter commands issued in this cycle."""

    t: float
    x: np.ndarray
    xd: np.ndarray
    xdd: np.ndarray
    force: np.ndarray
    line: int
    state: ProgramState
    progress: float
    commands: tuple[ParameterCommand, ...] = ()


def path_limits(chain: Chain, limits: Limits, feed: float | None) -> tuple[float, float, float]:
    """Limits (V, A, J) on s_dot, s_ddot, s_dddot that keep every group within its limits.

    With d1, d2, d3 bounding |q'|, |q''|, |q'''| of a group (chain rule, module docstring):
    d1 V <= v, d2 V^2 + d1 A <= a, d3 V^3 + 3 d2 V A + d1 J <= j. Curvature (d2 > 0) takes at
    most CENTRIPETAL_SHARE of a and a quarter of j for each of its two jerk terms."""
    d1, d2, d3 = chain.bounds()
    speed = math.inf if feed is None else feed
    for g, lim in enumerate(limits.groups()):
        if d1[g] > 0.0:
            speed = min(speed, lim.velocity / d1[g])
        if d2[g] > 0.0:
            speed = min(speed, math.sqrt(CENTRIPETAL_SHARE * lim.acceleration / d2[g]))
        if d3[g] > 0.0:
            speed = min(speed, (0.25 * lim.jerk / d3[g]) ** (1.0 / 3.0))
    accel = math.inf
    for g, lim in enumerate(limits.groups()):
        if d1[g] > 0.0:
            accel = min(accel, (lim.acceleration - d2[g] * speed**2) / d1[g])
        if d2[g] > 0.0:
            accel = min(accel, 0.25 * lim.jerk / (3.0 * d2[g] * speed))
    jerk = math.inf
    for g, lim in enumerate(limits.groups()):
        if d1[g] > 0.0:
            jerk = min(jerk, (lim.jerk - d3[g] * speed**3 - 3.0 * d2[g] * speed * accel) / d1[g])
    return speed, accel, jerk


# ruckig plans profiles of at most about 7,600 s (its result -101 beyond, measured); a move that
# long is a typo in F more often than a wish, so it is refused with its line, not split.
MAX_MOVE_DURATION = 7000.0  # s


class PlanningError(ValueError):
    """A motion that the time law cannot be planned for."""


def _first_line(exc: Exception) -> str:
    """The first non-empty line of ruckig's message, without its tag and the dump of its input."""
    line = next((line.strip() for line in str(exc).splitlines() if line.strip()), type(exc).__name__)
    return line.removeprefix("[ruckig]").removesuffix("input:").strip()


class _Planner:
    """1-DoF ruckig on the normalised path parameter u = s/L in [0, 1], durations on the dt grid."""

    def __init__(self, dt: float):
        self.dt = dt
        self.otg = Ruckig(1, dt)

    def _input(self, state, limits_u):
        inp = InputParameter(1)
        inp.duration_discretization = DurationDiscretization.Discrete
        inp.current_position, inp.current_velocity, inp.current_acceleration = ([v] for v in state)
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = ([v] for v in limits_u)
        return inp

    def _calculate(self, inp) -> Trajectory:
        trajectory = Trajectory(1)
        try:
            result = self.otg.calculate(inp, trajectory)
        except (ValueError, RuntimeError) as exc:     # codes the bindings lack, e.g. -101 (duration)
            raise PlanningError(f"the time law cannot be planned ({exc})") from None
        except RuckigError as exc:   # limits ruckig's arithmetic cannot join (e.g. a tiny F beside a huge jerk)
            raise PlanningError(f"the time law cannot be planned at this feed (ruckig: {_first_line(exc)}); "
                                "change F or the move's length") from None
        if result not in (Result.Working, Result.Finished):
            raise PlanningError(f"the time law cannot be planned (ruckig: {result})")
        return trajectory

    def to_end(self, state, limits_u) -> Trajectory:
        """Time-optimal jerk-limited profile from state (u, du, ddu) to standstill at u = 1."""
        inp = self._input(state, limits_u)
        inp.target_position, inp.target_velocity, inp.target_acceleration = [1.0], [0.0], [0.0]
        return self._calculate(inp)

    def to_standstill(self, state, limits_u) -> Trajectory:
        """Jerk-limited braking of u to du = ddu = 0 (velocity interface): the controlled stop."""
        inp = self._input(state, limits_u)
        inp.control_interface = ControlInterface.Velocity
        inp.target_velocity, inp.target_acceleration = [0.0], [0.0]
        return self._calculate(inp)


@dataclass(eq=False)
class _ChainPlan:
    """Consecutive Motions joined smoothly, with their limits on u and the planned profile."""

    motions: list[Motion]
    chain: Chain | None = None
    limits_u: tuple[float, float, float] | None = None
    trajectory: Trajectory | None = None
    duration: float = 0.0

    def accepts(self, motion: Motion) -> bool:
        last = self.motions[-1]
        return (motion.feed == last.feed and motion.rapid == last.rapid
                and joins_smoothly(last.segment, motion.segment))

    def finish(self, limits: Limits, planner: _Planner) -> None:
        """Plan the chain's time law; GCodeError naming the first block of a chain that cannot be."""
        self.chain = Chain([m.segment for m in self.motions])
        v, a, j = path_limits(self.chain, limits, self.motions[0].feed)
        length = self.chain.length
        self.limits_u = (v / length, a / length, j / length)
        first = self.motions[0].line
        if length / v > MAX_MOVE_DURATION:
            raise GCodeError([Diagnostic(first, 1, "motion", f"this move takes {length / v:.0f} s at its feed, more than the "
                                         f"{MAX_MOVE_DURATION:.0f} s the interpolator plans: raise F or split the move")])
        try:
            self.trajectory = planner.to_end((0.0, 0.0, 0.0), self.limits_u)
        except PlanningError as exc:
            raise GCodeError([Diagnostic(first, 1, "motion", str(exc))]) from None
        self.duration = self.trajectory.duration

    def line_at(self, u: float) -> int:
        return self.motions[self.chain.locate(u * self.chain.length)].line


@dataclass(eq=False)
class _Run:
    """A ruckig profile of u being sampled; braking=True for pause/cancel stops."""

    plan: _ChainPlan
    trajectory: Trajectory
    braking: bool
    steps: int
    k: int = 0
    state: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def advance(self, dt: float) -> bool:
        """Move one cycle; True when the profile has ended (exactly at its target, at rest)."""
        self.k += 1
        if self.k >= self.steps:
            end = 1.0 if not self.braking else self.trajectory.at_time(self.trajectory.duration)[0][0]
            self.state = (end, 0.0, 0.0)
            return True
        p, v, a = self.trajectory.at_time(self.k * dt)
        self.state = (p[0], v[0], a[0])
        return False


def _steps(duration: float, dt: float) -> int:
    return max(int(round(duration / dt)), 0)


@dataclass(eq=False)
class _Cursor:
    """Where the program is: item index, active profile or dwell, planned time already done."""

    index: int = 0
    run: _Run | None = None
    dwell_left: int | None = None
    done_time: float = 0.0
    line: int = 0
    pending: ParameterCommand | None = None
    q: np.ndarray = field(default_factory=lambda: np.zeros(9))
    qd: np.ndarray = field(default_factory=lambda: np.zeros(9))
    qdd: np.ndarray = field(default_factory=lambda: np.zeros(9))


class Interpolator:
    """Step-by-step set-point generator for a parsed Program, one step() per control cycle dt.

    wait_for_commands: stop in WAITING at each parameter command until command_done() (the node);
    otherwise commands are only reported in the Setpoint. optional_stop: honour M1."""

    def __init__(self, program: Program, limits: Limits = Limits(), dt: float = 1e-3, *,
                 wait_for_commands: bool = False, optional_stop: bool = False):
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt must be finite and positive, got {dt!r}")
        self.dt = dt
        self.limits = limits
        self.wait_for_commands = wait_for_commands
        self.optional_stop = optional_stop
        self.error = ""
        self._planner = _Planner(dt)
        self._items = self._plan(program)
        self.duration = sum(i.duration for i in self._items if isinstance(i, (_ChainPlan, Dwell)))
        self._k = 0
        self._cur = _Cursor(q=program.start.copy())
        self._state = ProgramState.RUNNING
        self._aborting = False

    def _plan(self, program: Program) -> list:
        items: list = []
        for block in program.blocks:
            if isinstance(block, Motion):
                if items and isinstance(items[-1], _ChainPlan) and items[-1].accepts(block):
                    items[-1].motions.append(block)
                else:
                    items.append(_ChainPlan([block]))
            else:
                items.append(block)
        for item in items:
            if isinstance(item, _ChainPlan):
                item.finish(self.limits, self._planner)
        return items

    @property
    def state(self) -> ProgramState:
        return self._state

    @property
    def line(self) -> int:
        return self._cur.line

    @property
    def t(self) -> float:
        return self._k * self.dt

    @property
    def progress(self) -> float:
        cur = self._cur
        if self._state is ProgramState.DONE or self.duration == 0.0:
            return 1.0 if self._state is ProgramState.DONE else 0.0
        done = cur.done_time
        if cur.run is not None:
            done += min(max(cur.run.state[0], 0.0), 1.0) * cur.run.plan.duration
        elif cur.dwell_left is not None:
            dwell = self._items[cur.index]
            done += dwell.duration - cur.dwell_left * self.dt
        return min(max(done / self.duration, 0.0), 1.0)

    # ---- commands from the operator ---------------------------------------------------------

    def pause(self) -> bool:
        """Controlled jerk-limited stop on the path; True if accepted (only while RUNNING)."""
        if self._state is not ProgramState.RUNNING:
            return False
        self._brake(ProgramState.PAUSING, ProgramState.PAUSED)
        return True

    def cancel(self) -> bool:
        """Controlled jerk-limited stop, then CANCELLED; True unless the program already ended."""
        if self._state in TERMINAL_STATES:
            return False
        if self._state is ProgramState.PAUSING:
            self._state = ProgramState.CANCELLING
        elif self._state is not ProgramState.CANCELLING:
            self._brake(ProgramState.CANCELLING, ProgramState.CANCELLED)
        return True

    def abort(self, reason: str, brake: bool = True) -> bool:
        """Fail the program with ``reason`` (a fault of the robot, not the operator's cancel): a
        jerk-limited stop on the path, then FAILED; at once without ``brake`` (time does not advance).
        True unless the program already ended or is being aborted."""
        if self._state in TERMINAL_STATES or (self._aborting and brake):
            return False
        if not self._aborting:
            self.error = f"line {self.line}: {reason}"
        self._aborting = True
        if not brake:
            self._state = ProgramState.FAILED
            return True
        if self._state is ProgramState.WAITING:
            self._state = ProgramState.FAILED
            return True
        return self.cancel()

    def resume(self) -> bool:
        """Continue after pause() or M0/M1 (also while still braking); True if accepted."""
        if self._state not in (ProgramState.PAUSED, ProgramState.PAUSING):
            return False
        run = self._cur.run
        if run is not None and run.braking:
            trajectory = self._planner.to_end(run.state, run.plan.limits_u)
            self._cur.run = _Run(run.plan, trajectory, False, _steps(trajectory.duration, self.dt), state=run.state)
        self._state = ProgramState.RUNNING
        return True

    def command_done(self, success: bool, message: str = "") -> None:
        """Acknowledge the parameter command the interpolator is WAITING for."""
        if self._state is not ProgramState.WAITING:
            return
        command = self._cur.pending
        self._cur.pending = None
        if success:
            self._state = ProgramState.RUNNING
        else:
            self._state = ProgramState.FAILED
            self.error = f"line {command.line}: setting {command.node}.{command.parameter} failed: {message}"

    def _cancelled(self) -> ProgramState:
        return ProgramState.FAILED if self._aborting else ProgramState.CANCELLED

    def _brake(self, braking: ProgramState, stopped: ProgramState) -> None:
        """Switch the active profile to a standstill stop, unless that would run past the chain end:
        then the running profile, which ends at rest exactly at the chain end, is the stop."""
        run = self._cur.run
        if run is None or run.braking:
            # standing still already (between items, dwell, waiting)
            self._state = self._cancelled() if stopped is ProgramState.CANCELLED else stopped
            return
        trajectory = self._planner.to_standstill(run.state, run.plan.limits_u)
        if trajectory.position_extrema[0].max <= 1.0:
            self._cur.run = _Run(run.plan, trajectory, True, _steps(trajectory.duration, self.dt), state=run.state)
        self._state = braking

    # ---- the cycle ---------------------------------------------------------------------------

    def step(self) -> Setpoint:
        """Advance one cycle dt and return the set-point for the new time."""
        self._k += 1
        commands: list[ParameterCommand] = []
        self._settle(commands)
        cur = self._cur
        if cur.run is None and self._state is ProgramState.RUNNING and cur.dwell_left is None \
                and cur.index < len(self._items):
            plan = self._items[cur.index]
            cur.run = _Run(plan, plan.trajectory, False, _steps(plan.duration, self.dt))
        if cur.run is not None and self._state in (ProgramState.RUNNING, ProgramState.PAUSING, ProgramState.CANCELLING):
            self._advance_run()
        elif cur.dwell_left is not None and self._state is ProgramState.RUNNING:
            cur.dwell_left -= 1
            if cur.dwell_left <= 0:
                self._finish_item(self._items[cur.index].duration)
        self._settle(commands)
        return Setpoint(self.t, cur.q[:6].copy(), cur.qd[:6].copy(), cur.qdd[:6].copy(), cur.q[6:].copy(),
                        cur.line, self._state, self.progress, tuple(commands))

    def _advance_run(self) -> None:
        cur = self._cur
        run = cur.run
        ended = run.advance(self.dt)
        chain = run.plan.chain
        u, du, ddu = run.state
        s, ds, dds = u * chain.length, du * chain.length, ddu * chain.length
        q, dq, ddq = chain.at(s)
        cur.q, cur.qd, cur.qdd = q, dq * ds, ddq * ds**2 + dq * dds
        cur.line = run.plan.line_at(u)
        if not ended:
            return
        if run.braking:
            self._state = self._cancelled() if self._state is ProgramState.CANCELLING else ProgramState.PAUSED
            return
        cur.q = chain.end.copy()  # exactly the programmed end point
        cur.run = None
        self._finish_item(run.plan.duration)
        if self._state is ProgramState.PAUSING:
            self._state = ProgramState.PAUSED
        elif self._state is ProgramState.CANCELLING:
            self._state = self._cancelled()

    def _finish_item(self, duration: float) -> None:
        self._cur.index += 1
        self._cur.done_time += duration
        self._cur.dwell_left = None

    def _settle(self, commands: list[ParameterCommand]) -> None:
        """Execute the zero-duration items at the cursor while RUNNING and idle; start dwells."""
        cur = self._cur
        while self._state is ProgramState.RUNNING and cur.run is None and cur.dwell_left is None:
            if cur.index >= len(self._items):
                self._state = ProgramState.DONE
                return
            item = self._items[cur.index]
            if isinstance(item, _ChainPlan):
                return
            cur.line = item.line
            if isinstance(item, Dwell):
                cur.dwell_left = _steps(item.duration, self.dt)
                if cur.dwell_left == 0:
                    self._finish_item(item.duration)
                continue
            self._finish_item(0.0)
            if isinstance(item, ParameterCommand):
                commands.append(item)
                if self.wait_for_commands:
                    cur.pending = item
                    self._state = ProgramState.WAITING
            elif isinstance(item, ProgramStop) and (self.optional_stop or not item.optional):
                self._state = ProgramState.PAUSED


@dataclass(frozen=True, eq=False)
class Samples:
    """A whole program sampled every dt, starting with the start pose at t = 0 (arrays by cycle)."""

    t: np.ndarray
    x: np.ndarray
    xd: np.ndarray
    xdd: np.ndarray
    force: np.ndarray
    line: np.ndarray
    state: tuple[ProgramState, ...]
    commands: tuple[ParameterCommand, ...]


def sample_program(program: Program, limits: Limits = Limits(), dt: float = 1e-3) -> Samples:
    """Run a program to its end (M0/M1 resumed at once, commands acknowledged) and collect the set-points."""
    interp = Interpolator(program, limits, dt)
    q0 = program.start
    points = [Setpoint(0.0, q0[:6].copy(), np.zeros(6), np.zeros(6), q0[6:].copy(), 0, interp.state, 0.0)]
    while points[-1].state not in TERMINAL_STATES:
        if interp.state is ProgramState.PAUSED:
            interp.resume()
        points.append(interp.step())
    return Samples(
        t=np.array([p.t for p in points]),
        x=np.array([p.x for p in points]),
        xd=np.array([p.xd for p in points]),
        xdd=np.array([p.xdd for p in points]),
        force=np.array([p.force for p in points]),
        line=np.array([p.line for p in points]),
        state=tuple(p.state for p in points),
        commands=tuple(c for p in points for c in p.commands),
    )

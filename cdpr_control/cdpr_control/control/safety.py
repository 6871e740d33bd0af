"""Safety checks of the command path (issue: "safety in the loop").

The monitor looks at one control period's inputs and reports faults; the joint command
(:mod:`cdpr_control.control.joint_command`) holds its last safe set-point while a holding fault is present.
Faults: cable force beyond its limits, position lag error beyond a bound, forward kinematics not
converged, a stale input, and non-finite input values.

The force watch (:class:`ForceWatch`, on by default) is the latched part: a cable force outside
[f_min - tol, f_max + tol] for longer than ``force_limit_time``, a force rate beyond
``max_force_rate`` force ranges per second (a growing oscillation), or a position error beyond
``max_position_lag`` trips it once and for good (until released). The joint command then goes to
the last command that the forces followed within their limits for ``safe_history`` seconds, and
stays there: the controllers' outputs of that moment frozen, not the diverging ones.
"""
from __future__ import annotations

import math
from collections import deque
from math import isfinite
from dataclasses import dataclass

import numpy as np

from cdpr_control import kernels
from cdpr_control.model.memo import Memo

FORCE_LIMIT = "force_limit"
POSITION_LAG = "position_lag"
FK_NOT_CONVERGED = "fk_not_converged"
STALE_INPUT = "stale_input"
NON_FINITE = "non_finite"
WORKSPACE = "workspace"          # the set-point left the wrench-feasible workspace (joint command)
FORCE_WATCH = "force_watch"      # the latched force watch tripped (ForceWatch)


def all_finite(values) -> bool:
    """Whether every value is finite (``values``: a numpy array of any shape or a flat sequence of
    numbers): one sum (a NaN or inf makes it non-finite), element by element only when the sum is
    not finite (finite values near 1e308 may overflow it). At 1 kHz this costs a fraction of
    np.isfinite(v).all() on a short vector; the project's one finiteness check of short vectors."""
    if isinstance(values, np.ndarray):
        values = values.ravel().tolist()
    return isfinite(sum(values)) or all(map(isfinite, values))


def braking(faults: list) -> bool:
    """Whether a holding fault other than the position lag is present: the joint command then
    brakes while the set-point may go on, so the position error says nothing about the control
    (the force watch leaves it out)."""
    return any(fault.holds and fault.code != POSITION_LAG for fault in faults)


def _floats(value) -> list:
    return (value if isinstance(value, np.ndarray) else np.asarray(value, dtype=float)).ravel().tolist()


def _finite_floats(name: str, value, faults: list) -> list | None:
    """value's entries as floats when it is given and finite; None otherwise (a fault when not finite)."""
    if value is None:
        return None
    # (a plain vector's tolist is _floats': the calls spared; a subclass may ravel otherwise)
    values = value.tolist() if type(value) is np.ndarray and value.ndim == 1 else _floats(value)
    if all_finite(values):
        return values
    faults.append(Fault(NON_FINITE, f"{name} has non-finite values", True))
    return None


def _inside(f: list, f_min, f_max, tolerance: float) -> bool:
    """Whether every force is within the tightest limits (so within its own: rounding is monotonic,
    f_i >= min f >= max f_min - tol >= f_min,i - tol); False asks for the element-wise check."""
    return not f or (min(f) >= max(_floats(f_min)) - tolerance and max(f) <= min(_floats(f_max)) + tolerance)


_F64 = np.dtype(float)


@dataclass
class SafetyConfig:
    force_tolerance: float = 0.0        # N beyond [f_min, f_max] tolerated before a fault
    max_position_lag: float = 0.05      # m, |r_d - r|
    max_orientation_lag: float = 0.1    # rad, |phi_d - phi|
    stale_timeout: float = 0.05         # s without a new input
    hold_on_force_limit: bool = False   # a force fault holds the command while it lasts (else it is reported only)
    # the latched force watch (ForceWatch); the times and the rate were chosen from measurement on
    # the Mini (docs/control.md, "Safety"): the shipped programs and contacts stay below a quarter
    # of max_force_rate, the diverging gains of issue 28 cross it within 10 ms (tests/control/test_force_watch.py)
    force_watch: bool = True            # trip the latched hold to the last safe command
    force_band: float = 0.05            # -, the watch's tolerance beyond [f_min, f_max] as a share of f_max - f_min
    force_limit_time: float = 0.05      # s a cable force may stay beyond the band
    max_force_rate: float = 20.0        # 1/s: |df/dt| (filtered) in force ranges (f_max - f_min) per second
    force_rate_filter: float = 0.005    # s, PT1 time constant of the force rate
    safe_history: float = 0.1           # s of clean periods after a command that make it the safe one
    # s from the first period before the force rate is watched: the start-up transient (the plant
    # settling from its initial tension while the encoders calibrate Δq_0, 0.1 s) is no oscillation
    # (measured: 66 kN/s on an IPAnema 3 cable 9 ms after start at a border pose, limit 58 kN/s)
    rate_watch_delay: float = 0.3

    def validate(self) -> None:
        bounds = {"force_tolerance": self.force_tolerance, "max_position_lag": self.max_position_lag,
                  "max_orientation_lag": self.max_orientation_lag, "stale_timeout": self.stale_timeout,
                  "force_band": self.force_band, "force_limit_time": self.force_limit_time, "force_rate_filter": self.force_rate_filter,
                  "safe_history": self.safe_history, "rate_watch_delay": self.rate_watch_delay}
        bad = [f"{k} = {v}" for k, v in bounds.items() if not v >= 0]
        if not self.max_force_rate > 0:
            bad.append(f"max_force_rate = {self.max_force_rate} (must be > 0)")
        if bad:
            raise ValueError(f"safety bounds must be >= 0: {', '.join(bad)}")


@dataclass
class Fault:
    code: str
    message: str
    holds: bool


def _extreme_limits(f_min: np.ndarray, f_max: np.ndarray) -> tuple:
    """(max f_min, min f_max) of float64 limits, (None, None) for others or empty ones."""
    if f_min.dtype != _F64 or f_max.dtype != _F64:
        return None, None
    return max(f_min.ravel().tolist(), default=None), min(f_max.ravel().tolist(), default=None)


class SafetyMonitor:
    def __init__(self, config: SafetyConfig | None = None):
        self.config = config or SafetyConfig()
        self.config.validate()
        self._limits = Memo()    # max f_min, min f_max of the last limits' bytes and dtypes (None: not float64, or empty)

    def _inside(self, f: list, f_min, f_max, tolerance: float) -> bool:
        """:func:`_inside` with max f_min and min f_max kept while the limits' bytes repeat (the
        robot's limits, every period; bytes and dtype fix the values); other limits (not float64
        arrays, or empty) take _inside."""
        if not f:
            return True
        if type(f_min) is np.ndarray and type(f_max) is np.ndarray:
            key = (f_min.tobytes(), f_max.tobytes(), f_min.dtype, f_max.dtype)
            lo, hi = self._limits(key, _extreme_limits, f_min, f_max)
            if lo is not None and hi is not None:
                return min(f) >= lo - tolerance and max(f) <= hi + tolerance
        return _inside(f, f_min, f_max, tolerance)

    def check(self, now: float, *, f=None, f_min=None, f_max=None, x_d=None, x=None,
              fk_converged: bool = True, input_times: dict[str, float] | None = None) -> list[Fault]:
        """Faults of one period; inputs that are None are not checked."""
        c = self.config
        faults: list[Fault] = []
        # as Python floats, each input's finiteness once: at 1 kHz numpy's per-call cost on these
        # short vectors is more than the checks
        f_values = _finite_floats("f", f, faults)
        x_d_values = _finite_floats("x_d", x_d, faults)
        x_values = _finite_floats("x", x, faults)
        if f_values is not None and not self._inside(f_values, f_min, f_max, c.force_tolerance):
            below, above = f < f_min - c.force_tolerance, f > f_max + c.force_tolerance
            for i in np.flatnonzero(below):
                faults.append(Fault(FORCE_LIMIT, f"cable {i + 1}: {f[i]:.1f} N below f_min {f_min[i]:.1f} N", c.hold_on_force_limit))
            for i in np.flatnonzero(above):
                faults.append(Fault(FORCE_LIMIT, f"cable {i + 1}: {f[i]:.1f} N above f_max {f_max[i]:.1f} N", c.hold_on_force_limit))
        if x_d_values is not None and x_values is not None:
            dr = math.dist(x_d_values[:3], x_values[:3])
            dphi = math.dist(x_d_values[3:], x_values[3:])
            if dr > c.max_position_lag:
                faults.append(Fault(POSITION_LAG, f"position lag {dr * 1e3:.1f} mm > {c.max_position_lag * 1e3:.1f} mm", True))
            if dphi > c.max_orientation_lag:
                faults.append(Fault(POSITION_LAG, f"orientation lag {np.rad2deg(dphi):.2f} deg > {np.rad2deg(c.max_orientation_lag):.2f} deg", True))
        if not fk_converged:
            faults.append(Fault(FK_NOT_CONVERGED, "forward kinematics did not converge", True))
        # none stale when the oldest is not (now - t falls as t grows: rounding is monotonic; a NaN
        # first in min, or a NaN now, fails the test and goes through every input)
        if input_times and not now - min(input_times.values()) <= c.stale_timeout:
            for name, t in input_times.items():
                if now - t > c.stale_timeout:
                    # (a fixed text: the report on /diagnostics changes with the message, not every period)
                    faults.append(Fault(STALE_INPUT, f"stale input {name}: older than {1e3 * c.stale_timeout:.0f} ms", True))
        return faults


class ForceWatch:
    """The latched safety hold of the joint command: detects a runaway and names the command to hold.

    Per period (:meth:`update`) it watches the measured cable forces f and the pose error:

    * a cable outside [f_min - tol, f_max + tol], tol = ``force_band`` (f_max - f_min), for longer
      than ``force_limit_time`` (consecutive periods);
    * a growing oscillation: the force rate df/dt, PT1-filtered over ``force_rate_filter``, away
      from the force set-point f_d (a force that follows a step of its set-point, a new tension
      level, moves towards it) beyond ``max_force_rate`` (f_max - f_min) per second on any cable.
      A rate, not an energy: it is per cable, needs no model of the platform, and on the Mini
      crossed the limit within 10 ms of an unstable gain while the shipped programs and contacts stayed
      below a quarter of it;
    * a position error |r_d - r| beyond ``max_position_lag``.

    The first of these trips it: :attr:`fault` (code FORCE_WATCH, holding) stays set until
    :meth:`release`. :attr:`safe` is what the joint command holds then: the set-point pose x_d of
    the tripping period (on the planned path, where the platform is) with the force-control outputs
    and the force set-point frozen at the newest period that was followed by ``safe_history``
    seconds of clean periods (every force within the band, every rate below half the limit):
    θ_d = IK(x_safe + Σ offsets_safe) - Δq_CFC,safe, the tension the forces followed within their
    limits, not the diverging outputs (before a clean stretch, the first period's outputs); the
    joint command restores f_d,safe slowly on top (:mod:`cdpr_control.control.joint_command`). The thesis
    has no such layer (its safety is the drives' own limits); it is the project's.
    """

    def __init__(self, config: SafetyConfig, dt: float):
        config.validate()
        self.config, self.dt = config, dt
        self.fault: Fault | None = None
        self.safe: tuple | None = None               # (x_safe (6,), offset_safe (6,), Δq_CFC,safe (m,), f_d,safe) once tripped
        self._outputs: tuple | None = None           # (offset, Δq_CFC, f_d) of the newest safe period
        self._history: deque = deque(maxlen=max(1, int(round(config.safe_history / dt))) + 1)
        self._clean = 0
        # per cable: periods beyond the band in a row, filtered df/dt [N/s], that rate away from f_d
        # [N/s], the last force [N] (force_watch_period's state; None until a finite period)
        self._state: np.ndarray | None = None
        self._out = np.empty(5)                      # force_watch_period's summary of the period
        self._bounds = Memo()    # _bands of the last limits' bytes (the configuration: cleared by configure)
        self._periods = 0                            # watched so far (the rate from rate_watch_delay on)
        self.configure(config)
        kernels.warm_up()                            # force_watch_period loaded now, not in the first period

    def configure(self, config: SafetyConfig) -> None:
        """New settings (a node's parameters) for the next periods; a tripped watch stays tripped."""
        config.validate()
        self.config = config
        self._limit_periods = int(round(config.force_limit_time / self.dt))
        self._rate_from = int(round(config.rate_watch_delay / self.dt))
        self._alpha = self.dt / (config.force_rate_filter + self.dt)        # PT1 of the rate
        self._history = deque(self._history, maxlen=max(1, int(round(config.safe_history / self.dt))) + 1)
        self._bounds.clear()

    def release(self) -> None:
        """End the hold (an operator's decision): the watch starts again from the next period."""
        self.fault = None
        self._state = None
        self._clean = self._periods = 0
        self._history.clear()
        self.safe = self._outputs = None

    def _limits(self, f_min, f_max, m: int) -> tuple:
        """(f_min, f_max, tol, lower edge, upper edge, rate limit), each a list of m floats, kept
        while the limits' bytes repeat (the robot's, every period), and the last three as the rows of
        an array (force_watch_period's bounds)."""
        f_min, f_max = np.asarray(f_min, dtype=float), np.asarray(f_max, dtype=float)
        return self._bounds((f_min.tobytes(), f_max.tobytes(), m), self._bands, f_min, f_max, m)

    def _bands(self, f_min, f_max, m: int) -> tuple:
        f_min, f_max = np.broadcast_to(f_min, (m,)), np.broadcast_to(f_max, (m,))
        tol = self.config.force_band * (f_max - f_min)
        bounds = tuple(v.tolist() for v in (f_min, f_max, tol, f_min - tol, f_max + tol,
                                            self.config.max_force_rate * (f_max - f_min)))
        return bounds, np.array(bounds[3:])

    def update(self, f, f_min, f_max, x_d, offset, dq_cfc, f_d=None, x=None) -> Fault | None:
        """One period: measured forces f (m,) [N] (None or non-finite: not watched this period), the
        limits, the set-point pose x_d (6,), the period's summed offset (6,) and Δq_CFC (m,) as the
        joint command adds them, the force set-point f_d (m,) (None: unknown), the estimated pose x
        (None: not watched) -> the latched fault, None while all is well."""
        if self.fault is not None or not self.config.force_watch:
            return self.fault
        self._remember(np.array(offset, dtype=float), np.array(dq_cfc, dtype=float),
                       None if f_d is None else np.array(f_d, dtype=float))
        values = None if f is None else _vector(f)
        m = 0 if values is None else len(values)
        fresh = self._state is None or self._state.shape[1] != m     # the first period: the rate from 0
        if values is None or (fresh and not all_finite(values)):
            self._clean = 0
            return None
        bounds, bounds_array = self._limits(f_min, f_max, m)
        if fresh:
            self._state = np.zeros((4, m))
            self._state[3] = values
        targets = values if f_d is None else _vector(f_d)
        if targets.shape != (m,):
            raise ValueError(f"f_d needs {m} forces like f, got {targets.shape[0]}")
        if not force_watch_period(values, targets, f_d is not None, bounds_array, self._state, self._alpha,
                                  1.0 / self.dt, self._out):
            self._clean = 0
            return None
        clean, longest, i_longest, worst, i_worst = self._out.tolist()
        self._periods += 1
        self.fault = (self._band(values, bounds, longest, int(i_longest))
                      or (self._oscillation(values, bounds, worst, int(i_worst)) if self._periods > self._rate_from
                          else None) or self._lag(x_d, x))
        self._clean = self._clean + 1 if clean else 0
        if self._clean >= len(self._history) and len(self._history) == self._history.maxlen:
            self._outputs = self._history[0]
        if self.fault is not None:
            self.safe = (np.array(x_d, dtype=float), *self._outputs)
        return self.fault

    def _remember(self, offset: np.ndarray, dq_cfc: np.ndarray, f_d) -> None:
        if self._outputs is None:
            self._outputs = (offset, dq_cfc, f_d)    # the first period: the robot stood there
        elif self._outputs[2] is None and f_d is not None:
            # the first force set-point (in the graph it may come a period after the first command):
            # without it a trip before the first clean stretch restored no tension
            self._outputs = (*self._outputs[:2], f_d)
        self._history.append((offset, dq_cfc, f_d))

    def _band(self, f: np.ndarray, bounds: tuple, longest: float, i: int) -> Fault | None:
        """Cable i beyond [f_min - tol, f_max + tol] for ``longest`` periods (the longest run),
        longer than force_limit_time."""
        if longest <= self._limit_periods:
            return None
        f_min, f_max, tol, lower = bounds[:4]
        side = f"below f_min {f_min[i]:.1f} N" if f[i] < lower[i] else f"above f_max {f_max[i]:.1f} N"
        return Fault(FORCE_WATCH, f"force watch: cable {i + 1}: {f[i]:.1f} N {side} (tolerance {tol[i]:.3g} N) "
                     f"for {1e3 * longest * self.dt:.0f} ms (limit {1e3 * self.config.force_limit_time:.0f} ms)", True)

    def _oscillation(self, f: np.ndarray, bounds: tuple, worst: float, i: int) -> Fault | None:
        """The filtered force rate away from f_d (any direction without f_d) of cable i, ``worst``
        times max_force_rate force ranges per second (the largest), beyond it."""
        if worst <= 1.0:
            return None
        return Fault(FORCE_WATCH, f"force watch: cable {i + 1}: force rate {abs(self._state[1, i]):.0f} N/s beyond "
                     f"{bounds[5][i]:.0f} N/s (a growing oscillation; at {f[i]:.1f} N)", True)

    def _lag(self, x_d, x) -> Fault | None:
        if x_d is None or x is None:
            return None
        dr = math.dist(_floats(x_d)[:3], _floats(x)[:3])
        if not dr > self.config.max_position_lag:
            return None
        return Fault(FORCE_WATCH, f"force watch: position error {1e3 * dr:.1f} mm beyond "
                     f"{1e3 * self.config.max_position_lag:.1f} mm", True)


def _vector(values) -> np.ndarray:
    """values as force_watch_period takes them: a flat C-contiguous float64 array (kernels.vector)."""
    v = kernels.vector(values)
    return v if v.ndim == 1 else v.ravel()


def _force_watch_period(f, f_d, has_f_d: bool, bounds, state, alpha: float, inv_dt: float, out) -> bool:
    """One period of :class:`ForceWatch`'s per-cable counters and rates on Python floats (at 1 kHz
    numpy's per-call cost on 8 values is more than the arithmetic), the reference of its compiled
    twin: f (m,) the measured forces [N]; f_d (m,) their set-point, read when has_f_d (then only a
    rate away from it counts: a force that follows a new set-point moves towards it; else any
    rate); bounds (3, m) per cable the band's lower and upper edge [N] and the rate limit [N/s];
    state (4, m) per cable the periods beyond the band in a row, the filtered df/dt (PT1 of alpha,
    inv_dt = 1 / dt) [N/s], that rate away from f_d [N/s] and the last f [N], updated in place;
    out (5,) <- (clean: every force within the band and every rate below half its limit, the
    longest run beyond the band, its cable, the largest rate away from f_d in limits, its cable; the
    first cable of equal ones) -> whether f is finite (else nothing is changed)."""
    values = f.tolist()
    if not all_finite(values):
        return False
    lower, upper, limit = bounds.tolist()
    outside, rate, away, prev = state.tolist()
    targets = f_d.tolist()
    clean = True
    for i, fi in enumerate(values):
        out_i = fi < lower[i] or fi > upper[i]
        outside[i] = outside[i] + 1.0 if out_i else 0.0
        r = rate[i] = rate[i] + alpha * ((fi - prev[i]) * inv_dt - rate[i])
        away[i] = (r if fi > targets[i] else -r if fi < targets[i] else 0.0) if has_f_d else abs(r)
        clean = clean and not out_i and abs(r) < 0.5 * limit[i]
    excess = [a / lim for a, lim in zip(away, limit)]
    longest, worst = max(outside), max(excess)
    state[:] = (outside, rate, away, values)
    out[:] = (clean, longest, outside.index(longest), worst, excess.index(worst))
    return True


force_watch_period = kernels.law("force_watch_period", _force_watch_period, kernels.force_watch_period)

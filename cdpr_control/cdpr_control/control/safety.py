"""Safety checks of the command path (issue: "safety in the loop").

The monitor looks at one control period's inputs and reports faults; the joint command
(:mod:`cdpr_control.control.joint_command`) holds its last safe set-point while a holding fault is present.
Faults: cable force beyond its limits, position lag error beyond a bound, forward kinematics not
converged, a stale input, and non-finite input values.
"""
from __future__ import annotations

import math
from math import isfinite
from dataclasses import dataclass

import numpy as np

FORCE_LIMIT = "force_limit"
POSITION_LAG = "position_lag"
FK_NOT_CONVERGED = "fk_not_converged"
STALE_INPUT = "stale_input"
NON_FINITE = "non_finite"
WORKSPACE = "workspace"          # the set-point left the wrench-feasible workspace (joint command)


def all_finite(values) -> bool:
    """Whether every value is finite (``values``: a numpy array of any shape or a flat sequence of
    numbers): one sum (a NaN or inf makes it non-finite), element by element only when the sum is
    not finite (finite values near 1e308 may overflow it). At 1 kHz this costs a fraction of
    np.isfinite(v).all() on a short vector; the project's one finiteness check of short vectors."""
    if isinstance(values, np.ndarray):
        values = values.ravel().tolist()
    return isfinite(sum(values)) or all(map(isfinite, values))


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
    hold_on_force_limit: bool = False   # a force fault holds the command (else it is reported only)

    def validate(self) -> None:
        if min(self.force_tolerance, self.max_position_lag, self.max_orientation_lag, self.stale_timeout) < 0:
            raise ValueError("safety bounds must be >= 0")


@dataclass
class Fault:
    code: str
    message: str
    holds: bool


class SafetyMonitor:
    def __init__(self, config: SafetyConfig | None = None):
        self.config = config or SafetyConfig()
        self.config.validate()
        self._limits_key: tuple | None = None     # the raw bytes and dtypes of the last f_min, f_max
        self._limits = (None, None)               # their max f_min, min f_max (None: not float64, or empty)

    def _inside(self, f: list, f_min, f_max, tolerance: float) -> bool:
        """:func:`_inside` with max f_min and min f_max kept while the limits' bytes repeat (the
        robot's limits, every period; bytes and dtype fix the values); other limits (not float64
        arrays, or empty) take _inside."""
        if not f:
            return True
        if type(f_min) is np.ndarray and type(f_max) is np.ndarray:
            key = (f_min.tobytes(), f_max.tobytes(), f_min.dtype, f_max.dtype)
            if key != self._limits_key:
                self._limits_key = key
                self._limits = (max(f_min.ravel().tolist(), default=None), min(f_max.ravel().tolist(), default=None)) \
                    if f_min.dtype == _F64 and f_max.dtype == _F64 else (None, None)
            lo, hi = self._limits
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

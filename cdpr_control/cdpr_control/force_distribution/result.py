"""Result of a cable force distribution (2.40) and its check against the cable limits (2.39).

Every algorithm ends in :func:`finish`, so all of them report the same things in the same way:
the forces f, a status (feasible / overloaded / infeasible, numbered as in
cdpr_msgs/ForceDistribution), the per-cable limit violation, the residual |A^T f + w|, the
iteration count and the solve time. f is never NaN: a non-finite candidate is replaced by the
reference force clipped into the limits and reported as infeasible.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

# A force counts as inside its limits when it is off by less than this, relative to the largest
# limit (3e-6 N for f_max = 3000 N); feasible forces are then clipped exactly into the limits.
LIMIT_RTOL = 1e-9
# |A^T f + w| relative to |w| + |A^T| |f| above which a solver's answer is not trusted.
RESIDUAL_RTOL = 1e-7


class Status(IntEnum):
    """Outcome of one distribution; the values match cdpr_msgs/ForceDistribution.STATUS_*."""

    FEASIBLE = 0      # f_min <= f <= f_max and A^T f = -w
    OVERLOADED = 1    # feasible only with f_max raised within the overload factor (3.6.2)
    INFEASIBLE = 2    # no feasible distribution; f is the method's fallback, see its docstring


@dataclass(slots=True)
class DistributionResult:
    """Cable forces for one pose (f of shape (m,)) or a batch (f of shape (..., m)).

    For one pose, status is a :class:`Status`, residual and iterations are Python scalars; for a
    batch they are arrays over the leading dimensions. violation is >= 0 per cable: how far f
    lies outside [f_min, f_max] [N] (zero when feasible). f_min/f_max are the limits used (f_max
    above the nominal one when overloaded); solve_time is the wall time of the whole call [s].
    """

    f: np.ndarray
    status: Status | np.ndarray
    violation: np.ndarray
    residual: float | np.ndarray
    iterations: int | np.ndarray
    solve_time: float
    method: str
    f_ref: np.ndarray
    f_min: np.ndarray
    f_max: np.ndarray

    @property
    def feasible(self) -> bool | np.ndarray:
        """True where the limits hold (possibly raised: OVERLOADED counts as feasible)."""
        if self.f.ndim == 1:
            return self.status != Status.INFEASIBLE
        return self.status != Status.INFEASIBLE.value

    @property
    def max_violation(self) -> float | np.ndarray:
        """Largest violation over the cables [N], 0 when feasible."""
        v = np.maximum.reduce(self.violation, axis=-1)   # what .max() calls, without its Python wrapper
        return float(v) if self.f.ndim == 1 else v


def limit_tolerance(f_min, f_max) -> float:
    """Absolute tolerance [N] on the limits (2.39): LIMIT_RTOL times the largest limit."""
    return LIMIT_RTOL * max(1.0, float(np.abs(f_max).max()), float(np.abs(f_min).max()))


def violation(f, f_min, f_max) -> np.ndarray:
    """Per-cable distance of f outside [f_min, f_max] [N], >= 0."""
    return np.maximum(np.maximum(f_min - f, f - f_max), 0.0)


def finish(method, AT, w, f, ok, f_min, f_max, f_ref, iterations, t0, status_ok=Status.FEASIBLE,
           tol=None):
    """Check f against (2.39)/(2.40) and package it as a :class:`DistributionResult`.

    ok (bool or (...) array) is the algorithm's own verdict; a pose is feasible when ok holds, f
    is finite, within the limits up to :func:`limit_tolerance` and balances the wrench up to
    RESIDUAL_RTOL. Feasible forces are clipped exactly into the limits. status_ok is the status
    given to feasible poses (OVERLOADED when the limits passed in are raised ones); tol
    overrides :func:`limit_tolerance` (callers that know it save its cost).
    """
    f = np.asarray(f, dtype=float)
    if tol is None:
        tol = limit_tolerance(f_min, f_max)
    if f.ndim == 1:
        return _finish_one(method, AT, w, f, ok, f_min, f_max, f_ref, iterations, t0, status_ok, tol)
    AT, w = np.asarray(AT, dtype=float), np.asarray(w, dtype=float)
    f_min, f_max, f_ref = (np.broadcast_to(np.asarray(v, dtype=float), f.shape)
                           for v in (f_min, f_max, f_ref))
    finite = np.isfinite(f).all(axis=-1)
    if not np.all(finite):
        f = np.where(finite[..., None], f, np.clip(f_ref, f_min, f_max))
    v = violation(f, f_min, f_max)
    with np.errstate(invalid="ignore", over="ignore"):
        r = np.einsum("...ij,...j->...i", AT, f) + w
        residual = np.sqrt(np.einsum("...i,...i->...", r, r))
        scale = np.sqrt(np.einsum("...i,...i->...", w, w)) + np.sqrt(
            np.einsum("...ij,...ij->...", AT, AT) * np.einsum("...i,...i->...", f, f)
        )
        balanced = residual <= RESIDUAL_RTOL * scale
    feasible = ok & finite & (v.max(axis=-1) <= tol) & balanced
    f = np.where(feasible[..., None], np.clip(f, f_min, f_max), f)
    v = np.where(feasible[..., None], 0.0, v)
    residual = np.where(np.isfinite(residual), residual, np.inf)
    status = np.where(feasible, np.uint8(status_ok), np.uint8(Status.INFEASIBLE))
    iterations = np.broadcast_to(np.asarray(iterations, dtype=np.int64), feasible.shape)
    return DistributionResult(f, status, v, residual, iterations, time.perf_counter() - t0, method,
                              f_ref, f_min, f_max)


def _finish_one(method, AT, w, f, ok, f_min, f_max, f_ref, iterations, t0, status_ok, tol):
    """:func:`finish` for one pose, with as few numpy calls as possible (the 1 kHz path).

    ``ndarray.dot`` rather than ``@``: the same BLAS call and numbers, at half the call's cost for
    arrays this small (0.6 against 1.2-1.3 us, numpy 2.4)."""
    AT = AT if type(AT) is np.ndarray else np.asarray(AT, dtype=float)
    w = w if type(w) is np.ndarray else np.asarray(w, dtype=float)
    r = AT.dot(f)
    r += w
    residual = math.sqrt(r.dot(r))
    if not math.isfinite(residual):
        ok = False
        f = np.minimum(np.maximum(f_ref, f_min), f_max)
        r = AT.dot(f)
        r += w
        residual = math.sqrt(r.dot(r)) if np.isfinite(r).all() else math.inf
    v = f_min - f
    np.maximum(v, f - f_max, out=v)
    worst = max(v.tolist())                               # faster than v.max() for m = 8
    feasible = ok and worst <= tol and (
        residual <= RESIDUAL_RTOL * math.sqrt(w.dot(w))   # cheap sufficient test first
        or residual <= RESIDUAL_RTOL * (math.sqrt(w.dot(w)) + math.sqrt(float(np.vdot(AT, AT)) * f.dot(f))))
    if feasible:
        if worst > 0.0:
            f = np.minimum(np.maximum(f, f_min), f_max)
        v.fill(0.0)
        status = Status.FEASIBLE if status_ok is Status.FEASIBLE else Status(status_ok)
    else:
        np.maximum(v, 0.0, out=v)
        status = Status.INFEASIBLE
    return DistributionResult(f, status, v, residual, int(iterations), time.perf_counter() - t0,
                              method, f_ref, f_min, f_max)

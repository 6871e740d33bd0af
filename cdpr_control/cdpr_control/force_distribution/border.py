"""Behaviour at the workspace border, section 3.6.2, and the 1 kHz entry point ForceDistributor.

When the nominal problem (2.40) has no solution (DAQP reports infeasibility or hits the iteration
limit, the thesis' observation of the iteration count kappa), the maximum cable force is raised
within the drives' overload capacity (the IPAnema 3 drives deliver three times their continuous
torque for a short time):

    f_max' = (1 + delta) f_max,   0 <= delta <= overload_factor - 1 .

delta follows the least raise that makes the pose feasible, delta_req (a small LP), times
(1 + margin) so the raised set keeps an interior; delta_req is a continuous function of the pose,
so f stays continuous when the trajectory crosses the border. With a rate the raise is also
smooth in time (hysteresis on the way back). Result status: OVERLOADED.

If even the full overload does not help, the QP returns the least-violating solution,

    min 1/2 |s|^2 + eps/2 |f - f_ref|^2 + mu/2 |f - f_prev|^2
    s.t.  A^T f = -w,  f_min - s <= f <= f_max' + s,  s >= 0,

which still balances the wrench and is unique (eps > 0). The violation alone is often flat along
a direction of the kernel (two cables off their limits, the others free), where the tiny eps term
would decide and the solution could run through the valley within one step; the proximal term
to the previous set-point f_prev (weight mu) makes it move there gradually instead, so f stays
continuous in time and meets the QP's solution at the border. Status INFEASIBLE; violation says
by how much each cable is off, so a controller can act on it (e.g. stop the motion). The
closed-form methods keep their own continuous fallback (CF's solution: "the exceeding of the
cable limits does not influence the algorithm").
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from cdpr_control.force_distribution.methods import METHODS, distribute
from cdpr_control.force_distribution.qp import DEFAULT_ITER_LIMIT, QPSolver, closed_form_one
from cdpr_control.force_distribution.result import DistributionResult, Status, finish

_INF = 1e30       # DAQP's "no bound"


@dataclass(frozen=True)
class BorderPolicy:
    """How :class:`ForceDistributor` behaves where the nominal limits admit no solution."""

    overload_factor: float = 1.0      # f_max may rise to this multiple (1.0: never; thesis: <= 3)
    margin: float = 0.05              # raise by (1 + margin) times the least raise needed
    rate: float | None = None         # max change of delta per second [1/s]; None: instant
    eps: float = 1e-6                 # weight of |f - f_ref|^2 in the least-violating problem
    mu: float = 0.1                   # weight of |f - f_prev|^2 there (smoothing in time)

    def validate(self) -> None:
        if not self.overload_factor >= 1.0:
            raise ValueError(f"overload_factor must be >= 1, got {self.overload_factor}")
        if not self.margin >= 0.0 or not self.eps > 0.0 or not self.mu >= 0.0:
            raise ValueError(f"need margin >= 0, eps > 0, mu >= 0, got {self.margin}, {self.eps}, {self.mu}")
        if self.rate is not None and not self.rate > 0.0:
            raise ValueError(f"rate must be > 0 or None, got {self.rate}")


class ForceDistributor:
    """Cable force set-points for a controller: one pose per call, warm-started, border-aware.

    method: one of METHODS; backend: the QP backend (default DAQP, warm-started). f_ref None
    means (f_min + f_max)/2; use f_ref = f_min for the minimal tension level.
    """

    def __init__(self, m: int, f_min, f_max, f_ref=None, method: str = "qp", backend: str = "daqp",
                 border: BorderPolicy = BorderPolicy(), iter_limit: int = DEFAULT_ITER_LIMIT):
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
        border.validate()
        self.m = m
        self.method = method
        self.backend = backend
        self.border = border
        self.qp = QPSolver(m, f_min, f_max, f_ref, backend, iter_limit)
        self.delta = 0.0       # current relative raise of f_max
        self.f_prev = None     # last set-point, anchor of the least-violating solution

    @property
    def f_min(self) -> np.ndarray:
        return self.qp.f_min

    @property
    def f_max(self) -> np.ndarray:
        return self.qp.f_max

    @property
    def f_ref(self) -> np.ndarray:
        return self.qp.f_ref

    def set_reference(self, f_ref) -> None:
        """Change the tension level stepless (3.27): any f_min <= f_ref <= f_max."""
        self.qp.f_ref = np.broadcast_to(np.asarray(f_ref, dtype=float), (self.m,)).copy()

    def solve(self, AT, w, dt: float | None = None) -> DistributionResult:
        """f_d for A^T (n, m) and the desired wrench w (n,); dt [s] for the rate of the raise."""
        t0 = time.perf_counter()
        res = self._nominal(AT, w, self.f_max)
        if res.status == Status.FEASIBLE and self.delta == 0.0:
            self.f_prev = res.f
            return res
        if not (np.isfinite(AT).all() and np.isfinite(w).all()):
            self.f_prev = None                       # nothing to balance: no border handling
            return res
        iterations = res.iterations
        target = 0.0
        if res.status == Status.INFEASIBLE and self.border.overload_factor > 1.0:
            need, its = required_overload(AT, w, self.f_min, self.f_max, self.border.overload_factor - 1.0)
            iterations += its
            target = (1.0 + self.border.margin) * need
        self.delta = self._rate_limited(target, dt)
        f_max = (1.0 + self.delta) * self.f_max
        if self.delta > 0.0:
            res = self._nominal(AT, w, f_max)
            iterations += res.iterations
            if res.status == Status.FEASIBLE and np.any(res.f > self.f_max + 1e-9 * self.f_max):
                res = replace(res, status=Status.OVERLOADED)
        if res.status == Status.INFEASIBLE and self.method == "qp":
            mu = 0.0 if self.f_prev is None else self.border.mu
            f, _, its = least_violating(AT, w, self.f_min, f_max, self.f_ref, self.border.eps,
                                         self.f_prev, mu)
            iterations += its
            res = finish("qp", AT, w, f, False, self.f_min, f_max, self.f_ref, 0, t0)
        self.f_prev = res.f
        return replace(res, iterations=int(iterations), solve_time=time.perf_counter() - t0)

    def reset(self) -> None:
        """Forget warm start, overload state and the previous set-point."""
        self.qp.reset()
        self.delta = 0.0
        self.f_prev = None

    def _nominal(self, AT, w, f_max) -> DistributionResult:
        if self.method == "qp":
            return self.qp.solve(AT, w) if f_max is self.f_max else self.qp.solve(AT, w, f_max=f_max)
        return distribute(AT, w, self.f_min, f_max, self.f_ref, self.method)

    def _rate_limited(self, target: float, dt: float | None) -> float:
        top = self.border.overload_factor - 1.0
        if self.border.rate is not None and dt is not None:
            step = self.border.rate * dt
            target = min(max(target, self.delta - step), self.delta + step)
        return min(max(target, 0.0), top)


def required_overload(AT, w, f_min, f_max, delta_max: float) -> tuple[float, int]:
    """The least delta in [0, delta_max] for which f_min <= f <= (1 + delta) f_max, A^T f = -w,
    has a solution (an LP solved by DAQP), and DAQP's iterations; inf if there is none."""
    import daqp

    m, n = len(f_min), len(w)
    A = np.zeros((n + m, m + 1))
    A[:n, :m] = AT
    A[n:, :m] = np.eye(m)
    A[n:, m] = -f_max                                   # f - delta f_max <= f_max
    bu = np.r_[np.full(m, _INF), delta_max, -w, f_max]
    bl = np.r_[f_min, 0.0, -w, np.full(m, -_INF)]
    sense = np.r_[np.zeros(m + 1, dtype=np.int32), np.full(n, 5, dtype=np.int32), np.zeros(m, dtype=np.int32)]
    x, _, exitflag, info = daqp.solve(None, np.r_[np.zeros(m), 1.0], A, bu, bl, sense)
    solved = exitflag == 1 and np.isfinite(x[m])
    return (float(max(x[m], 0.0)) if solved else np.inf), info["iterations"]


def least_violating(AT, w, f_min, f_max, f_ref, eps: float, f_prev=None, mu: float = 0.0
                    ) -> tuple[np.ndarray, bool, int]:
    """The wrench-balancing f with the least squared limit violation (see the module docstring).

    Returns (f, solved, DAQP iterations); if DAQP fails, f is the closed form (2.42).
    """
    import daqp

    m, n = len(f_min), len(w)
    H = np.diag(np.r_[np.full(m, eps + mu), np.ones(m)])
    anchor = eps * np.asarray(f_ref, dtype=float) + (0.0 if f_prev is None else mu * np.asarray(f_prev))
    A = np.zeros((n + 2 * m, 2 * m))
    A[:n, :m] = AT
    A[n:n + m, :m] = A[n + m:, :m] = np.eye(m)
    A[n:n + m, m:] = -np.eye(m)                         # f - s <= f_max
    A[n + m:, m:] = np.eye(m)                           # f + s >= f_min
    bu = np.r_[np.full(m, _INF), np.full(m, _INF), -w, f_max, np.full(m, _INF)]
    bl = np.r_[np.full(m, -_INF), np.zeros(m), -w, np.full(m, -_INF), f_min]
    sense = np.zeros(n + 4 * m, dtype=np.int32)
    sense[2 * m:2 * m + n] = 5                          # equality rows A^T f = -w
    x, _, exitflag, info = daqp.solve(H, np.r_[-anchor, np.zeros(m)], A, bu, bl, sense)
    if exitflag != 1:
        return closed_form_one(AT, w, f_ref), False, info["iterations"]
    return x[:m].copy(), True, info["iterations"]

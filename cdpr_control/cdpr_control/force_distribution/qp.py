"""Quadratic programming with reference force, (3.27)-(3.28):

    min 1/2 (f - f_ref)^T (f - f_ref)   subject to   f_min <= f <= f_max,  A^T f = -w .

f_ref = f_min gives the minimal, f_ref = (f_min + f_max)/2 the medium and f_ref = f_max the maximal
tension level, and anything in between (stepless, section 3.6.2).

Backends (selected by name):

* ``"kernel"``: exact and batched. By (*) of :mod:`.nullspace` the QP is the projection of
  lambda_0 = H^T f_ref onto the feasible polygon, solved by enumeration
  (:func:`.feasible_set.project`); needs r = m - n <= 2. No iterations, no tolerance games.
* ``"daqp"``: DAQP's dual active-set solver through its low-level ``daqp.Model`` with the
  arrays preallocated; the working set is kept between calls (warm start).
* ``"proxsuite"``: ProxQP (dense, box constraints), warm-started with the previous result.
* ``"qpsolvers"``: a plain ``qpsolvers.solve_qp(..., solver="daqp")`` call, cold every time:
  the reference the benchmark compares against.

Infeasible poses return the closed form f_CF (2.42) with status INFEASIBLE: continuous and
wrench-balancing, but outside the limits. The border behaviour of section 3.6.2 (overload,
least-violating solution) is :mod:`.border`'s job.
"""
from __future__ import annotations

import time

import daqp
import numpy as np

from cdpr_control.force_distribution.feasible_set import project
from cdpr_control.force_distribution.nullspace import forces, nullspace, reference_coordinates
from cdpr_control.force_distribution.problem import as_batch
from cdpr_control.force_distribution.result import DistributionResult, finish, limit_tolerance

BACKENDS = ("kernel", "daqp", "proxsuite", "qpsolvers")
# DAQP iterations after which a pose counts as infeasible: the thesis observes the iteration
# count kappa for this (section 3.6.2); warm-started solves need 0-3 on a trajectory.
DEFAULT_ITER_LIMIT = 100


def quadratic_program(AT, w, f_min, f_max, f_ref=None, backend="kernel") -> DistributionResult:
    """(3.27)-(3.28) for one pose or a batch; f_ref defaults to (f_min + f_max)/2.

    "kernel" solves the batch at once; the other backends run one warm-started
    :class:`QPSolver` along the batch in order (a trajectory benefits from the warm start).
    """
    if backend == "kernel":
        p = as_batch(AT, w, f_min, f_max, f_ref)
        ns = nullspace(p.AT, p.w)
        lam, ok, active = project(ns, reference_coordinates(ns, p.f_ref), p.f_min, p.f_max, p.tol)
        return p.result("qp", forces(ns, lam), ok, active)
    p = as_batch(AT, w, f_min, f_max, f_ref)
    solver = QPSolver(p.AT.shape[2], p.f_min[:, 0], p.f_max[:, 0], p.f_ref[:, 0], backend)
    if not p.shape:
        return solver.solve(p.AT[0], p.w[0], p.f_min[:, 0], p.f_max[:, 0], p.f_ref[:, 0])
    f = np.empty(p.f_ref.shape)
    ok = np.empty(p.AT.shape[0], dtype=bool)
    its = np.empty(p.AT.shape[0], dtype=np.int64)
    for k in range(p.AT.shape[0]):
        res = solver.solve(p.AT[k], p.w[k], p.f_min[:, k], p.f_max[:, k], p.f_ref[:, k])
        f[:, k], ok[k], its[k] = res.f, res.feasible, res.iterations
    return p.result("qp", f, ok, its)


class QPSolver:
    """(3.27)-(3.28) for one pose per call, warm-started from the previous call.

    f_min, f_max, f_ref (scalars or (m,)) are the defaults of :meth:`solve`; f_ref None means
    (f_min + f_max)/2. iter_limit caps DAQP's iterations (more signals infeasibility, 3.6.2).
    """

    def __init__(self, m: int, f_min, f_max, f_ref=None, backend: str = "daqp",
                 iter_limit: int = DEFAULT_ITER_LIMIT):
        if backend not in BACKENDS:
            raise ValueError(f"unknown QP backend {backend!r}; choose one of {', '.join(BACKENDS)}")
        self.m = m
        self.backend = backend
        self.f_min = np.broadcast_to(np.asarray(f_min, dtype=float), (m,)).copy()
        self.f_max = np.broadcast_to(np.asarray(f_max, dtype=float), (m,)).copy()
        self.f_ref = (self.f_min + self.f_max) / 2.0 if f_ref is None else np.broadcast_to(
            np.asarray(f_ref, dtype=float), (m,)).copy()
        self.tol = limit_tolerance(self.f_min, self.f_max)
        self._solve = {"kernel": _KernelBackend, "daqp": _DaqpBackend,
                       "proxsuite": _ProxsuiteBackend, "qpsolvers": _QpsolversBackend}[backend](m, iter_limit)

    def solve(self, AT, w, f_min=None, f_max=None, f_ref=None) -> DistributionResult:
        """f for A^T (n, m) and w (n,); limits and f_ref default to the constructor's."""
        t0 = time.perf_counter()
        tol = self.tol if f_min is None and f_max is None else None
        f_min = self.f_min if f_min is None else self._vector(f_min)
        f_max = self.f_max if f_max is None else self._vector(f_max)
        f_ref = self.f_ref if f_ref is None else self._vector(f_ref)
        f, ok, iterations = self._solve(AT, w, f_min, f_max, f_ref)
        if not ok:
            f = closed_form_one(AT, w, f_ref)
        return finish("qp", AT, w, f, ok, f_min, f_max, f_ref, iterations, t0, tol=tol)

    def reset(self) -> None:
        """Forget the warm start (the next solve starts cold)."""
        self._solve.reset()

    def _vector(self, v) -> np.ndarray:
        return np.broadcast_to(np.asarray(v, dtype=float), (self.m,))


def closed_form_one(AT, w, f_ref) -> np.ndarray:
    """f_CF (2.42) for one pose via least squares (the QP's fallback when infeasible)."""
    if not (np.isfinite(AT).all() and np.isfinite(w).all()):
        return np.array(f_ref, dtype=float)
    return f_ref - np.linalg.lstsq(AT, w + AT @ f_ref, rcond=None)[0]


class _DaqpBackend:
    """daqp.Model with preallocated bounds [f_max; -w] / [f_min; -w] and equality rows.

    Limits and f_ref are copied into the model only when they are other objects than last time
    (the 1 kHz loop passes the same arrays every cycle).
    """

    def __init__(self, m, iter_limit):
        self.m = m
        self.iter_limit = iter_limit
        self.model = None

    def reset(self):
        self.model = None

    def __call__(self, AT, w, f_min, f_max, f_ref):
        try:
            return self._call(AT, w, f_min, f_max, f_ref)
        except RuntimeError:   # DAQP refuses e.g. NaN data: no solution, and no warm start
            self.model = None
            return np.zeros(self.m), False, 0

    def _call(self, AT, w, f_min, f_max, f_ref):
        m = self.m
        A = np.ascontiguousarray(AT, dtype=float)
        if self.model is None:
            return self._setup(A, w, f_min, f_max, f_ref)
        bu, bl = self.bu, self.bl
        if f_min is not self.limits[0] or f_max is not self.limits[1]:
            bu[:m], bl[:m] = f_max, f_min
            self.limits = (f_min, f_max)
        np.negative(w, out=self.bu_w)
        np.negative(w, out=self.bl_w)
        if f_ref is not self.f_ref:
            self.f_ref = f_ref
            self.model.update(f=-np.asarray(f_ref, dtype=float), A=A, bupper=bu, blower=bl)
        else:
            self.model.update(A=A, bupper=bu, blower=bl)
        return self._solve()

    def _setup(self, A, w, f_min, f_max, f_ref):
        m, n = self.m, len(w)
        self.bu, self.bl = np.r_[f_max, -w].astype(float), np.r_[f_min, -w].astype(float)
        self.bu_w, self.bl_w = self.bu[m:], self.bl[m:]          # views for the wrench rows
        self.limits, self.f_ref = (f_min, f_max), f_ref
        sense = np.r_[np.zeros(m, dtype=np.int32), np.full(n, 5, dtype=np.int32)]
        self.model = daqp.Model()
        self.model.setup(np.eye(m), -np.asarray(f_ref, dtype=float), A, self.bu, self.bl, sense)
        settings = self.model.settings
        settings["iter_limit"] = self.iter_limit
        self.model.settings = settings
        return self._solve()

    def _solve(self):
        x, _, exitflag, info = self.model.solve()
        if exitflag != 1:      # the working set of a failed solve is no warm start
            self.model = None
            return x, False, info["iterations"]
        return x, True, info["iterations"]


class _ProxsuiteBackend:
    """ProxQP dense with box constraints, warm-started with the previous result."""

    def __init__(self, m, iter_limit):
        self.m = m
        self.iter_limit = iter_limit
        self.qp = None

    def reset(self):
        self.qp = None

    def __call__(self, AT, w, f_min, f_max, f_ref):
        from proxsuite import proxqp

        A = np.ascontiguousarray(AT, dtype=float)
        g, b = -np.asarray(f_ref, dtype=float), -np.asarray(w, dtype=float)
        l_box, u_box = np.asarray(f_min, dtype=float), np.asarray(f_max, dtype=float)
        if self.qp is None:
            self.qp = proxqp.dense.QP(self.m, A.shape[0], 0, True)
            s = self.qp.settings
            s.eps_abs, s.eps_rel, s.max_iter = 1e-9, 0.0, self.iter_limit
            s.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            self.qp.init(np.eye(self.m), g, A, b, None, None, None, l_box, u_box)
        else:
            self.qp.update(g=g, A=A, b=b, l_box=l_box, u_box=u_box)
        self.qp.solve()
        res = self.qp.results
        ok = res.info.status == proxqp.QPSolverOutput.PROXQP_SOLVED
        if not ok:
            self.qp = None
        return res.x.copy(), ok, int(res.info.iter)


class _QpsolversBackend:
    """Plain qpsolvers.solve_qp with DAQP: no warm start; iterations are not reported (0)."""

    def __init__(self, m, iter_limit):
        self.m = m

    def reset(self):
        pass

    def __call__(self, AT, w, f_min, f_max, f_ref):
        import qpsolvers

        x = qpsolvers.solve_qp(np.eye(self.m), -np.asarray(f_ref, dtype=float), A=AT,
                               b=-np.asarray(w, dtype=float), lb=f_min, ub=f_max, solver="daqp")
        return (np.zeros(self.m), False, 0) if x is None else (x, True, 0)


class _KernelBackend:
    """The exact batched kernel solver on a batch of one."""

    def __init__(self, m, iter_limit):
        pass

    def reset(self):
        pass

    def __call__(self, AT, w, f_min, f_max, f_ref):
        res = quadratic_program(AT, w, f_min, f_max, f_ref, backend="kernel")
        return res.f, res.feasible, res.iterations

"""Behaviour at the workspace border, section 3.6.2: infeasibility detection, overload of f_max,
least-violating continuous solution, and the warm-started 1 kHz entry point ForceDistributor."""
import numpy as np
import pytest

from cdpr_control import force_distribution as fd
from cdpr_control.force_distribution import BorderPolicy, ForceDistributor, Status
from cdpr_control.force_distribution.border import least_violating, required_overload
from cdpr_control.model.robot import load_robot
from cdpr_control.model.workspace import static_problem, with_platform_mass

F_MIN, F_MAX = 100.0, 3000.0


def path(n):
    """IPAnema 3 with m_p = 150 kg from the centre (0, 0, 1) out to (8, 3.5, 2), past the border."""
    robot = with_platform_mass(load_robot("ipanema3"), 150.0)
    s = np.linspace(0.0, 1.0, n)
    x = np.zeros((n, 6))
    x[:, 0], x[:, 1], x[:, 2] = 8.0 * s, 3.5 * s, 1.0 + s
    return static_problem(robot, x)


@pytest.fixture(scope="module")
def border_path():
    return path(1500)


def run(distributor, AT, w, dt=1e-3):
    out = [distributor.solve(A, ww, dt) for A, ww in zip(AT, w)]
    return out, np.array([r.f for r in out]), np.array([int(r.status) for r in out])


def test_required_overload_is_the_least_raise(border_path):
    AT, w = border_path
    outside = ~fd.wrench_feasible(AT, w, F_MIN, F_MAX)
    checked = 0
    for A, ww in zip(AT[outside][::40], w[outside][::40]):
        delta, _ = required_overload(A, ww, np.full(8, F_MIN), np.full(8, F_MAX), 2.0)
        if np.isfinite(delta):
            assert fd.wrench_feasible(A, ww, F_MIN, F_MAX * (1 + delta) + 1e-6)
            assert not fd.wrench_feasible(A, ww, F_MIN, F_MAX * (1 + 0.999 * delta))
            checked += 1
        else:                        # no raise of f_max helps: a cable would need less than f_min
            assert not fd.wrench_feasible(A, ww, F_MIN, F_MAX * 3.0)
    assert checked >= 3


def test_inside_the_workspace_the_distributor_is_the_qp(border_path):
    AT, w = border_path
    d = ForceDistributor(8, F_MIN, F_MAX, F_MIN, border=BorderPolicy(overload_factor=1.5))
    for A, ww in zip(AT[:200:20], w[:200:20]):
        res = d.solve(A, ww)
        exact = fd.quadratic_program(A, ww, F_MIN, F_MAX, F_MIN)
        assert res.status == Status.FEASIBLE and d.delta == 0.0
        np.testing.assert_allclose(res.f, exact.f, atol=1e-6)


def test_overload_then_least_violating_along_a_path_out_of_the_workspace(border_path):
    AT, w = border_path
    policy = BorderPolicy(overload_factor=1.5)
    results, F, S = run(ForceDistributor(8, F_MIN, F_MAX, F_MIN, border=policy), AT, w)
    changes = np.flatnonzero(np.diff(S))
    assert list(S[changes + 1]) == [Status.OVERLOADED, Status.INFEASIBLE]   # in this order, once
    for res, A, ww in zip(results, AT, w):
        assert np.isfinite(res.f).all()
        assert res.residual <= 1e-8 * (np.linalg.norm(ww) + np.linalg.norm(A) * np.linalg.norm(res.f))
        if res.status == Status.OVERLOADED:
            assert np.all(res.f <= res.f_max) and np.all(res.f >= F_MIN) and res.f.max() > F_MAX
            assert np.all(res.f_max <= 1.5 * F_MAX + 1e-9)
        if res.status == Status.INFEASIBLE:
            assert res.max_violation > 0.0 and np.allclose(res.f_max, 1.5 * F_MAX)
    steps = np.abs(np.diff(F, axis=0)).max(axis=1)
    assert np.all(steps[changes] < 10.0 * np.median(steps))     # no jump where the status changes
    assert steps.max() < 100.0                                   # nor anywhere else [N per step]


def test_without_overload_the_border_is_crossed_continuously(border_path):
    AT, w = border_path
    _, F, S = run(ForceDistributor(8, F_MIN, F_MAX, F_MIN), AT, w)
    changes = np.flatnonzero(np.diff(S))
    assert len(changes) == 1 and S[-1] == Status.INFEASIBLE
    steps = np.abs(np.diff(F, axis=0)).max(axis=1)
    assert steps[changes[0]] < 10.0 * np.median(steps)


def test_least_violating_violates_less_than_other_balancing_distributions(border_path):
    AT, w = border_path
    f_min, f_max, f_ref = np.full(8, F_MIN), np.full(8, F_MAX), np.full(8, 1550.0)
    rng = np.random.default_rng(0)
    sq = lambda f: np.sum(np.maximum(np.maximum(F_MIN - f, f - F_MAX), 0.0) ** 2, axis=0)   # noqa: E731
    for A, ww in zip(AT[-100::25], w[-100::25]):
        f, ok, _ = least_violating(A, ww, f_min, f_max, f_ref, eps=1e-9)
        assert ok and sq(f) > 0.0
        np.testing.assert_allclose(A @ f, -ww, atol=1e-6)
        H = np.linalg.svd(A)[2][6:].T
        others = f[:, None] + H @ rng.normal(size=(2, 500)) * rng.uniform(0.1, 500.0, 500)
        assert np.all(sq(others) >= sq(f) - 1e-6)
        cf = fd.closed_form(A, ww, F_MIN, F_MAX, f_ref).f
        assert sq(cf) >= sq(f) - 1e-6


def test_the_raise_of_f_max_is_rate_limited(border_path):
    AT, w = border_path
    d = ForceDistributor(8, F_MIN, F_MAX, F_MIN, border=BorderPolicy(overload_factor=2.0, rate=2.0))
    deltas = []
    for A, ww in zip(AT, w):
        d.solve(A, ww, dt=1e-3)
        deltas.append(d.delta)
    deltas = np.array(deltas)
    assert deltas.max() > 0.1
    assert np.all(np.abs(np.diff(deltas)) <= 2.0 * 1e-3 + 1e-12)


def test_closed_form_methods_keep_their_own_fallback(border_path):
    AT, w = border_path
    d = ForceDistributor(8, F_MIN, F_MAX, method="cf")
    res = d.solve(AT[-1], w[-1])
    assert res.status == Status.INFEASIBLE
    np.testing.assert_allclose(res.f, fd.closed_form(AT[-1], w[-1], F_MIN, F_MAX).f, atol=1e-9)


@pytest.mark.parametrize("backend", list(fd.BACKENDS))
def test_qp_solver_detects_infeasibility(backend, border_path):
    AT, w = border_path
    res = fd.QPSolver(8, F_MIN, F_MAX, backend=backend).solve(AT[-1], w[-1])
    assert res.status == Status.INFEASIBLE and res.max_violation > 0.0
    np.testing.assert_allclose(res.f, fd.closed_form(AT[-1], w[-1], F_MIN, F_MAX).f, atol=1e-6)


def test_iteration_limit_signals_infeasibility(border_path):
    """Section 3.6.2: a high iteration count kappa means no solution; the limit enforces it."""
    AT, w = border_path
    res = fd.QPSolver(8, F_MIN, F_MAX, F_MIN, iter_limit=1).solve(AT[0], w[0])
    assert res.status == Status.INFEASIBLE


def test_warm_start_needs_fewer_iterations(border_path):
    AT, w = border_path
    inside = slice(0, 1000)
    warm = fd.QPSolver(8, F_MIN, F_MAX, F_MIN)
    cold = fd.QPSolver(8, F_MIN, F_MAX, F_MIN)
    its_warm, its_cold = [], []
    for A, ww in zip(AT[inside], w[inside]):
        its_warm.append(warm.solve(A, ww).iterations)
        cold.reset()
        its_cold.append(cold.solve(A, ww).iterations)
    assert np.mean(its_warm) < 0.5 * np.mean(its_cold)


def test_policy_is_validated():
    for bad in (BorderPolicy(overload_factor=0.5), BorderPolicy(margin=-1.0), BorderPolicy(rate=0.0)):
        with pytest.raises(ValueError):
            ForceDistributor(8, F_MIN, F_MAX, border=bad)
    with pytest.raises(ValueError, match="unknown method"):
        ForceDistributor(8, F_MIN, F_MAX, method="lp")


@pytest.mark.parametrize("backend", list(fd.BACKENDS))
def test_nan_or_singular_structure_matrix_and_recovery(backend, border_path):
    AT, w = border_path
    d = ForceDistributor(8, F_MIN, F_MAX, F_MIN, backend=backend, border=BorderPolicy(overload_factor=1.5))
    nan, singular = AT[10].copy(), AT[11].copy()
    nan[0, 0] = np.nan
    singular[:, 1:4] = singular[:, :1]                    # four equal columns: rank 5
    statuses = []
    for A, ww in ((AT[9], w[9]), (nan, w[10]), (singular, w[11]), (AT[12], w[12])):
        res = d.solve(A, ww)
        assert np.isfinite(res.f).all()
        statuses.append(res.status)
    assert statuses == [Status.FEASIBLE, Status.INFEASIBLE, Status.INFEASIBLE, Status.FEASIBLE]

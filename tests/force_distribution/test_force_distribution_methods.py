"""Cable force algorithms of section 2.2.2 and the QP (3.27)-(3.28): equilibrium, limits, the
relations between the methods stated in the thesis, and the QP against DAQP/ProxQP/qpsolvers.

Most cases use a hand-made point-anchor robot (structure matrix (2.10) built here), so the
algorithms are checked independently of the project's kinematics; the IPAnema 3 cases use it.
"""
import numpy as np
import pytest

from cdpr_control import force_distribution as fd
from cdpr_control.force_distribution import Status
from cdpr_control.model.robot import load_robot
from cdpr_control.model.workspace import static_problem, with_platform_mass
from cdpr_test_nodes.force_problems import random_problems

F_MIN, F_MAX = 100.0, 3000.0
CLOSED_FORM = ("cf", "cfe", "pm", "acf", "ipm")


@pytest.fixture(scope="module")
def problems():
    return random_problems(400)


@pytest.fixture(scope="module")
def ipanema():
    """IPAnema 3 (m_p = 30 kg) at random positions over its frame, inside and outside the WFW."""
    robot = with_platform_mass(load_robot("ipanema3"), 30.0)
    rng = np.random.default_rng(1)
    x = np.zeros((3000, 6))
    x[:, :3] = rng.uniform([-8.0, -5.3, -0.3], [8.0, 5.3, 3.0], (3000, 3))
    x[:, 3:] = rng.uniform(-0.1, 0.1, (3000, 3))
    return static_problem(robot, x)


@pytest.fixture(scope="module")
def results(ipanema):
    AT, w = ipanema
    out = {method: fd.distribute(AT, w, F_MIN, F_MAX, method=method) for method in fd.METHODS}
    out["qp_min"] = fd.distribute(AT, w, F_MIN, F_MAX, F_MIN, "qp")
    out["qp_max"] = fd.distribute(AT, w, F_MIN, F_MAX, F_MAX, "qp")
    return out


def assert_valid(res, AT, w, f_min=F_MIN, f_max=F_MAX):
    """Feasible f: A^T f = -w to 1e-8 relative, limits to 1e-9; every f finite."""
    assert np.isfinite(res.f).all()
    ok = np.asarray(res.feasible)
    f, A, ww = res.f[ok], AT[ok], w[ok]
    scale = np.linalg.norm(ww, axis=-1) + np.linalg.norm(A, axis=(-2, -1)) * np.linalg.norm(f, axis=-1)
    residual = np.linalg.norm(np.einsum("...ij,...j->...i", A, f) + ww, axis=-1)
    assert np.all(residual <= 1e-8 * scale)
    assert np.all(f >= np.broadcast_to(f_min, f.shape) - 1e-9)
    assert np.all(f <= np.broadcast_to(f_max, f.shape) + 1e-9)
    assert np.all(res.violation[ok] == 0.0)


@pytest.mark.parametrize("batch", [5, 400])         # LAPACK SVD path and column-wise path
def test_general_solution_2_41(problems, batch):
    """f_ext = -A^{+T} w and an orthonormal kernel basis H orthogonal to it, (2.41)."""
    from cdpr_control.force_distribution.nullspace import nullspace

    AT, w = problems[0][:batch], problems[1][:batch]
    ns = nullspace(AT, w)
    assert ns.ok.all()
    f_ext, H = ns.f_ext.T, np.moveaxis(ns.H, -1, 0)                  # (B, m), (B, r, m)
    np.testing.assert_allclose(f_ext, -np.einsum("bij,bj->bi", np.linalg.pinv(AT), w), atol=1e-9)
    np.testing.assert_allclose(np.einsum("bij,brj->bir", AT, H), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("brm,bsm->brs", H, H), np.broadcast_to(np.eye(2), (batch, 2, 2)),
                               atol=1e-12)
    np.testing.assert_allclose(np.einsum("brm,bm->br", H, f_ext), 0.0, atol=1e-9)
    loose = nullspace(AT, w, orthonormal=False)                      # still solves (2.41)
    np.testing.assert_allclose(np.einsum("bij,jb->bi", AT, loose.f_ext), -w, atol=1e-9)


@pytest.mark.parametrize("method", list(fd.METHODS))
def test_feasible_results_balance_the_wrench_within_the_limits(method, problems, results, ipanema):
    AT, w = problems
    res = fd.distribute(AT, w, F_MIN, F_MAX, method=method)
    assert 0 < res.feasible.sum() < len(w)          # the sample has both kinds of poses
    assert_valid(res, AT, w)
    assert_valid(results[method], *ipanema)


def test_per_cable_limits_and_reference(problems):
    AT, w = problems
    rng = np.random.default_rng(2)
    f_min = rng.uniform(50.0, 150.0, 8)
    f_max = rng.uniform(2500.0, 3500.0, 8)
    for method in fd.METHODS:
        res = fd.distribute(AT, w, f_min, f_max, rng.uniform(f_min, f_max), method)
        assert res.feasible.any()
        assert_valid(res, AT, w, f_min, f_max)


def test_closed_form_is_2_42(problems):
    AT, w = problems
    f_ref = np.full(8, (F_MIN + F_MAX) / 2.0)
    expected = f_ref - np.einsum("bij,bj->bi", np.linalg.pinv(AT), w + AT @ f_ref)
    res = fd.closed_form(AT, w, F_MIN, F_MAX)
    np.testing.assert_allclose(res.f[res.feasible], expected[res.feasible], rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.f[~res.feasible], expected[~res.feasible], rtol=0, atol=1e-8)
    assert np.all(res.status[~res.feasible] == Status.INFEASIBLE)


def test_closed_form_is_the_2norm_optimum_of_the_solution_space(problems):
    """(2.42) minimises |f - f_ref| over A^T f = -w: moving along the kernel only increases it."""
    AT, w = problems
    res = fd.closed_form(AT[:50], w[:50], F_MIN, F_MAX)
    f_ref = (F_MIN + F_MAX) / 2.0
    for A, f in zip(AT[:50], res.f):
        H = np.linalg.svd(A)[2][6:].T
        step = H @ np.random.default_rng(3).normal(size=(2, 20)) * 10.0
        assert np.all(np.linalg.norm(f[:, None] + step - f_ref, axis=0) > np.linalg.norm(f - f_ref))


def test_puncture_equals_cfe_for_equal_limits_and_touches_f_min(problems, results):
    """Section 2.2.2: PM applied to CF gives the CFE result; at least one cable has f_min."""
    AT, w = problems
    for pm, cfe, cf in ((fd.puncture(AT, w, F_MIN, F_MAX),
                         fd.closed_form_energy_efficient(AT, w, F_MIN, F_MAX),
                         fd.closed_form(AT, w, F_MIN, F_MAX)),
                        (results["pm"], results["cfe"], results["cf"])):
        np.testing.assert_array_equal(pm.feasible, cfe.feasible)
        np.testing.assert_allclose(pm.f[pm.feasible], cfe.f[pm.feasible], rtol=0, atol=1e-8)
        on_cf = cf.feasible
        assert np.all(pm.feasible[on_cf])                     # feasible wherever CF is
        low = pm.f[on_cf].min(axis=1)
        top = pm.f[on_cf].max(axis=1)
        assert np.all(np.isclose(low, F_MIN, atol=1e-6) | np.isclose(top, F_MAX, atol=1e-6))
        assert np.all(pm.f[on_cf].sum(axis=1) <= cf.f[on_cf].sum(axis=1) + 1e-6)


def test_puncture_lies_on_the_line_from_f_ext_to_f_cf(problems):
    AT, w = problems
    pm = fd.puncture(AT, w, F_MIN, F_MAX)
    cf = fd.closed_form(AT, w, F_MIN, F_MAX)
    f_ext = -np.einsum("bij,bj->bi", np.linalg.pinv(AT), w)
    d = cf.f - f_ext
    t = np.einsum("bi,bi->b", pm.f - f_ext, d) / np.einsum("bi,bi->b", d, d)
    ok = pm.feasible
    np.testing.assert_allclose(pm.f[ok], f_ext[ok] + t[ok, None] * d[ok], atol=1e-7)
    assert np.all(t[cf.feasible] <= 1.0 + 1e-12)            # it only lowers the tension


def test_cfe_with_per_cable_limits_lowers_f_ref_towards_f_min(problems):
    """(2.45): f_CFE = f_CF(f_ref,e) with f_ref,e = f_min + t (f_ref - f_min), one cable at its limit."""
    AT, w = problems
    f_min = np.linspace(80.0, 150.0, 8)
    f_ref = np.full(8, 1500.0)
    cfe = fd.closed_form_energy_efficient(AT, w, f_min, F_MAX, f_ref)
    P = np.eye(8) - np.einsum("bij,bjk->bik", np.linalg.pinv(AT), AT)
    f_ext = -np.einsum("bij,bj->bi", np.linalg.pinv(AT), w)
    base, d = f_ext + P @ f_min, np.einsum("bij,j->bi", P, f_ref - f_min)
    t = np.einsum("bi,bi->b", cfe.f - base, d) / np.einsum("bi,bi->b", d, d)
    ok = cfe.feasible
    np.testing.assert_allclose(cfe.f[ok], base[ok] + t[ok, None] * d[ok], atol=1e-7)
    at_limit = np.isclose(cfe.f[ok], f_min, atol=1e-6) | np.isclose(cfe.f[ok], F_MAX, atol=1e-6)
    assert at_limit.any(axis=1).all()


def test_acf_is_cf_where_cf_is_feasible_and_reduces_at_most_r_times(results):
    cf, acf = results["cf"], results["acf"]
    np.testing.assert_allclose(acf.f[cf.feasible], cf.f[cf.feasible], atol=1e-9)
    assert np.all(acf.iterations[cf.feasible] == 1)
    assert np.all(acf.iterations <= 3)                      # CF + r = 2 reductions
    assert acf.feasible.sum() > cf.feasible.sum()
    reduced = acf.feasible & ~cf.feasible
    at_limit = np.isclose(acf.f[reduced], F_MIN, atol=1e-6) | np.isclose(acf.f[reduced], F_MAX, atol=1e-6)
    assert np.all(at_limit.sum(axis=1) >= acf.iterations[reduced] - 1)


def test_ipm_is_pm_on_w_cf_and_feasible_wherever_acf_is(results):
    ipm, pm, acf, cf = results["ipm"], results["pm"], results["acf"], results["cf"]
    np.testing.assert_allclose(ipm.f[cf.feasible], pm.f[cf.feasible], atol=1e-8)
    assert np.all(ipm.feasible[acf.feasible])
    both = ipm.feasible & acf.feasible
    assert np.all(ipm.f[both].sum(axis=1) <= acf.f[both].sum(axis=1) + 1e-6)


def test_qp_medium_agrees_with_acf_where_both_are_feasible(results):
    """Section 3.6.2: "the ACF and QP_med ... obtain the same result". Exactly so on W_CF; on the
    reduced part ACF's greedy choice of the cable to fix is occasionally not the QP's face."""
    qp, acf, cf = results["qp"], results["acf"], results["cf"]
    both = qp.feasible & acf.feasible
    diff = np.abs(qp.f - acf.f).max(axis=1)
    assert np.all(diff[cf.feasible] < 1e-8)
    assert np.mean(diff[both] < 1e-6) > 0.998
    assert abs(qp.f[both].mean() - acf.f[both].mean()) < 0.01 * acf.f[both].mean()


def test_qp_tension_level_is_stepless(results, ipanema):
    """f_ref = f_min puts a cable on f_min, f_ref = f_max one on f_max; the level in between."""
    qp_min, qp, qp_max = results["qp_min"], results["qp"], results["qp_max"]
    for r in (qp_min, qp_max):
        np.testing.assert_array_equal(r.feasible, qp.feasible)
    ok = qp.feasible
    assert np.all(np.isclose(qp_min.f[ok].min(axis=1), F_MIN, atol=1e-9))
    assert np.all(np.isclose(qp_max.f[ok].max(axis=1), F_MAX, atol=1e-9))
    AT, w = ipanema
    means = [fd.distribute(AT[ok][:300], w[ok][:300], F_MIN, F_MAX, f_ref, "qp").f.mean()
             for f_ref in np.linspace(F_MIN, F_MAX, 7)]
    assert np.all(np.diff(means) > 0.0)


@pytest.mark.parametrize("backend", ["daqp", "proxsuite", "qpsolvers"])
def test_qp_kernel_solver_matches_solver_libraries(backend, ipanema):
    AT, w = ipanema
    AT, w = AT[:150], w[:150]
    for f_ref in (F_MIN, 1550.0, F_MAX):
        exact = fd.quadratic_program(AT, w, F_MIN, F_MAX, f_ref, backend="kernel")
        other = fd.quadratic_program(AT, w, F_MIN, F_MAX, f_ref, backend=backend)
        np.testing.assert_array_equal(exact.feasible, other.feasible)
        ok = exact.feasible
        np.testing.assert_allclose(other.f[ok], exact.f[ok], rtol=0, atol=1e-5)
        assert_valid(other, AT, w)


def test_qp_solution_is_optimal_against_random_feasible_points(ipanema):
    """No feasible point on a random segment from the optimum is closer to f_ref (convexity)."""
    AT, w = ipanema
    res = fd.quadratic_program(AT[:200], w[:200], F_MIN, F_MAX, F_MIN)
    rng = np.random.default_rng(4)
    for A, ww, f in zip(AT[:200][res.feasible], w[:200][res.feasible], res.f[res.feasible]):
        H = np.linalg.svd(A)[2][6:].T
        g = f[:, None] + H @ rng.normal(size=(2, 200)) * rng.uniform(0.01, 50.0, 200)
        inside = np.all((g >= F_MIN) & (g <= F_MAX), axis=0)
        assert np.all(np.linalg.norm(g[:, inside] - F_MIN, axis=0) >= np.linalg.norm(f - F_MIN) - 1e-9)


def test_other_degrees_of_redundancy():
    """m = 6 (r = 0) and m = 7 (r = 1): the kernel QP still agrees with DAQP."""
    for m in (6, 7):
        AT, w = random_problems(60, m=m, seed=5, mass=(5.0, 40.0))
        exact = fd.quadratic_program(AT, w, F_MIN, F_MAX, F_MIN)
        daqp = fd.quadratic_program(AT, w, F_MIN, F_MAX, F_MIN, backend="daqp")
        np.testing.assert_array_equal(exact.feasible, daqp.feasible)
        np.testing.assert_allclose(exact.f[exact.feasible], daqp.f[exact.feasible], atol=1e-5)
        for method in CLOSED_FORM:
            assert_valid(fd.distribute(AT, w, F_MIN, F_MAX, method=method), AT, w)


def test_infeasible_pose_is_reported_not_returned_as_a_solution(problems):
    AT, w = problems
    w_heavy = w * 1e3                                        # 20-300 t on the platform
    for method in fd.METHODS:
        res = fd.distribute(AT[:20], w_heavy[:20], F_MIN, F_MAX, method=method)
        assert not res.feasible.any()
        assert np.all(res.status == Status.INFEASIBLE)
        assert np.all(res.max_violation > 0.0)
        assert np.isfinite(res.f).all()


def test_singular_or_nan_structure_matrix_gives_no_nan(problems):
    AT, w = problems
    bad = AT[:4].copy()
    bad[0, :, 1] = bad[0, :, 0]                             # two equal cables...
    bad[0, :, 2:4] = bad[0, :, 0:1]                         # ... four: rank 5
    bad[1, 0, 0] = np.nan
    bad[2, 3, :] = 0.0                                      # no moment about x: rank 5
    for method in fd.METHODS:
        res = fd.distribute(bad, w[:4], F_MIN, F_MAX, method=method)
        assert np.isfinite(res.f).all() and not res.feasible[:3].any()
        single = fd.distribute(bad[1], w[1], F_MIN, F_MAX, method=method)
        assert single.status == Status.INFEASIBLE and np.isfinite(single.f).all()


def test_single_pose_equals_batch_row_and_reports_python_types(problems):
    AT, w = problems
    batch = fd.distribute(AT[:5], w[:5], F_MIN, F_MAX, method="ipm")
    for k in range(5):
        one = fd.distribute(AT[k], w[k], F_MIN, F_MAX, method="ipm")
        np.testing.assert_allclose(one.f, batch.f[k], atol=1e-9)
        assert isinstance(one.status, Status) and isinstance(one.iterations, int)
        assert isinstance(one.feasible, bool) and one.solve_time > 0.0
        assert one.method == "ipm"


def test_names_are_checked(problems):
    AT, w = problems
    with pytest.raises(ValueError, match="unknown method"):
        fd.distribute(AT[0], w[0], F_MIN, F_MAX, method="simplex")
    with pytest.raises(ValueError, match="unknown QP backend"):
        fd.QPSolver(8, F_MIN, F_MAX, backend="gurobi")
    with pytest.raises(ValueError, match="f_min <= f_max"):
        fd.distribute(AT[0], w[0], F_MAX, F_MIN)
    with pytest.raises(ValueError, match="r = m - n <= 2"):
        fd.distribute(np.ones((6, 9)), np.zeros(6), F_MIN, F_MAX, method="qp")


def helix(n):
    """IPAnema 3 (m_p = 30 kg) on a tilting helix well inside the workspace, n samples."""
    robot = with_platform_mass(load_robot("ipanema3"), 30.0)
    s = np.linspace(0.0, 1.0, n)
    x = np.zeros((n, 6))
    x[:, 0], x[:, 1], x[:, 2] = 4.0 * np.cos(4 * np.pi * s), 2.5 * np.sin(4 * np.pi * s), 0.3 + 2.0 * s
    x[:, 3], x[:, 5] = 0.1 * np.sin(6 * np.pi * s), 0.2 * np.cos(2 * np.pi * s)
    return static_problem(robot, x)


@pytest.mark.parametrize("backend", ["kernel", "daqp"])
def test_qp_has_no_jumps_along_a_smooth_trajectory(backend):
    """Lipschitz in the pose: halving the sampling step halves the largest change per step
    (a jump would not shrink), for the minimal, medium and maximal tension level."""
    coarse, fine = helix(1000), helix(1999)
    for f_ref in (F_MIN, 1550.0, F_MAX):
        largest = []
        for AT, w in (coarse, fine):
            res = fd.quadratic_program(AT, w, F_MIN, F_MAX, f_ref, backend=backend)
            assert res.feasible.all()
            steps = np.abs(np.diff(res.f, axis=0)).max(axis=1)
            assert steps.max() < 5.0 * np.median(steps)          # no step stands out
            largest.append(steps.max())
        assert largest[1] < 0.6 * largest[0]

"""The cable force controller's integral part on the internal forces (CFCParams.internal_integral,
docs/load_compensation.md, "The CFC's integral part on the internal forces"): the integral part of (3.19) integrates only the component of the force
error in the nullspace of A^T(x_d) (2.41), so it exerts no wrench and moves no pose; the pose is the
OSPC's (3.16). Closed forms, an equilibrium on a clamped platform, the anti-windup inside the
projection, the decay of a part outside the nullspace, and the printed (3.19) where no x_d is given."""
import numpy as np
import pytest

from cdpr_control.control.cable_force_control import (CableForceControl, CableForceController, CFCParams,
                                                      internal_pi_update, nullspace_projector)
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot

X = np.array([2.160, 3.480, 1.535, 0.0, 0.0, np.radians(-5.0)])   # IPAnema 3 sweep pose #8 (cause B)


@pytest.fixture(scope="module")
def ipanema3():
    return load_robot("ipanema3")


@pytest.fixture(scope="module")
def AT(ipanema3):
    return inverse_kinematics(ipanema3, X).AT


def test_nullspace_projector_is_the_orthogonal_projector_onto_the_internal_forces(AT):
    P = nullspace_projector(AT)
    m = AT.shape[1]
    np.testing.assert_allclose(P @ P, P, atol=1e-12)                  # a projector
    np.testing.assert_allclose(P, P.T, atol=1e-12)                    # orthogonal
    np.testing.assert_allclose(AT @ P, 0.0, atol=1e-9)                # onto the nullspace of A^T
    assert np.trace(P) == pytest.approx(m - 6)                        # of dimension m - 6 (r = 2 for 8 cables)
    held = np.zeros(m, dtype=bool)
    held[3] = True
    Ph = nullspace_projector(AT, held)
    np.testing.assert_allclose(AT @ Ph, 0.0, atol=1e-9)
    np.testing.assert_allclose(Ph[3], 0.0, atol=1e-12)                # the held cable's component is 0
    assert np.trace(Ph) == pytest.approx(m - 7)


def test_nullspace_projector_of_a_rank_deficient_structure_matrix(AT):
    """A^T without full row rank (two cables' columns one, a degenerate pose): the 6x6 solve cannot
    give the projector; the pseudo-inverse's still projects onto the nullspace, of dimension m - 5."""
    singular = AT.copy()
    singular[5] = singular[4]                                          # rank 5
    P = nullspace_projector(singular)
    np.testing.assert_allclose(P @ P, P, atol=1e-9)
    np.testing.assert_allclose(singular @ P, 0.0, atol=1e-9)
    assert np.trace(P) == pytest.approx(singular.shape[1] - 5)


def test_internal_integral_is_the_projected_sum_and_exerts_no_wrench(AT):
    """Unsaturated, from 0: I_n = P sum_k K_p dt / T_i e_k (closed form), A^T I_n = 0 for any errors."""
    rng = np.random.default_rng(3)
    m, K_p, T_i, dt = AT.shape[1], 0.85, 0.1, 0.001
    P = nullspace_projector(AT)
    I = np.zeros(m)
    total = np.zeros(m)
    for _ in range(400):
        e = rng.normal(0.0, 20.0, m)
        I, saturated, u = internal_pi_update(e, K_p, T_i, dt, I, np.full(m, 1e4), np.full(m, 1e4), AT)
        total += K_p * dt / T_i * e
        assert not saturated.any()
        np.testing.assert_allclose(u, K_p * e + I)                    # the P part acts on the whole error
    np.testing.assert_allclose(I, P @ total, atol=1e-9)
    assert np.abs(AT @ I).max() < 1e-9 * np.abs(I).max()


def _clamped_platform(G):
    """The platform clamped at x_d: the forces follow the output f_c,out with a per-cable gain error G
    (the drives and cables stiffer or softer than modelled), no pose change."""
    return lambda f_out: G * f_out


@pytest.mark.parametrize("internal", [False, True])
def test_equilibrium_on_a_clamped_platform(AT, internal):
    """Steady state of the CFC on forces f = G f_c,out (f_c,out = f_d + u (3.22)). The printed (3.19)
    reaches f = f_d; the internal integral reaches the closed form: the error has no internal part
    (P e = 0), the integrator no wrench (A^T I = 0), and e + K_p G e + G I = (1 - G) f_d, the error
    in the wrench's directions left to the proportional part (on the robot to the force
    distribution's wrench filter and the OSPC, which a clamp does not have)."""
    m, dt = AT.shape[1], 0.001
    G = np.array([1.1, 0.92, 1.05, 0.95, 1.08, 1.0, 0.9, 1.12])        # |u| = |f_d / G - f_d| < F_sat
    f_d = np.array([900.0, 1400.0, 700.0, 1100.0, 950.0, 1300.0, 800.0, 1200.0])
    cfc = CableForceController(m, CFCParams(T_filter=0.0, internal_integral=internal), dt)
    cfc.reset(np.zeros(m))
    plant = _clamped_platform(G)
    f = plant(f_d)
    assert np.all(np.abs(f_d / G - f_d) < 0.8 * cfc.params.F_sat_p)
    for _ in range(6000):
        cfc.update(f_d, f, np.ones(m), np.full(m, 100.0), np.full(m, 3000.0), AT=AT if internal else None)
        f = plant(cfc.f_out)
    e, I = f_d - f, cfc.pi.integrator
    if not internal:
        np.testing.assert_allclose(f, f_d, rtol=1e-9)
        assert np.abs(AT @ I).max() > 1.0                  # the printed integral exerts a wrench
        return
    P = nullspace_projector(AT)
    K_p = cfc.params.K_p
    # the closed form: unknowns (e, I); equations above and P e = 0, (1 - P) I = 0
    M = np.block([[np.eye(m) + K_p * np.diag(G), np.diag(G)], [P, np.zeros((m, m))],
                  [np.zeros((m, m)), np.eye(m) - P]])
    rhs = np.concatenate([(1.0 - G) * f_d, np.zeros(2 * m)])
    solution, *_ = np.linalg.lstsq(M, rhs, rcond=None)
    np.testing.assert_allclose(M @ solution, rhs, atol=1e-6)    # consistent: the equilibrium exists
    np.testing.assert_allclose(e, solution[:m], atol=1e-6)
    np.testing.assert_allclose(I, solution[m:], atol=1e-6)
    np.testing.assert_allclose(AT @ I, 0.0, atol=1e-6)
    np.testing.assert_allclose(P @ e, 0.0, atol=1e-6)


def test_anti_windup_inside_the_projection(AT):
    """A large constant error drives outputs into the saturation: the integrator stays internal and
    within the output range, a held cable's integral part is not pushed further out, and the output
    leaves the saturation as soon as the error reverses."""
    m, K_p, T_i, dt = AT.shape[1], 0.85, 0.1, 0.001
    sat = np.full(m, 50.0)
    e = np.array([300.0, -20.0, 40.0, 10.0, -250.0, 5.0, 60.0, -30.0])
    I = np.zeros(m)
    for k in range(3000):
        I_new, saturated, u = internal_pi_update(e, K_p, T_i, dt, I, sat, sat, AT)
        assert np.abs(AT @ I_new).max() < 1e-9 * max(1.0, np.abs(I_new).max())
        assert np.all(I_new <= sat + 1e-9) and np.all(I_new >= -sat - 1e-9)
        free = K_p * e + I                                # held: saturated and pushed further out (as the PI's)
        out = ((free > sat) & (I_new > I + 1e-12)) | ((free < -sat) & (I_new < I - 1e-12))
        assert not out.any(), (k, np.flatnonzero(out))
        np.testing.assert_allclose(u, np.clip(K_p * e + I_new, -sat, sat))
        I = I_new
    assert saturated.any()
    u_back = internal_pi_update(-0.1 * e, K_p, T_i, dt, I, sat, sat, AT)[2]
    gone = saturated & (np.sign(u) == np.sign(e))
    assert np.all(np.abs(u_back[gone]) < sat[gone])       # leaves the limit at once


def test_a_part_outside_the_nullspace_decays_with_T_i(AT):
    """A wrench-exerting integrator (the printed (3.19)'s when the projection starts, after a contact)
    decays by the factor 1 - dt/T_i per period: no step of the drive command."""
    m, K_p, T_i, dt = AT.shape[1], 0.85, 0.1, 0.001
    P = nullspace_projector(AT)
    rng = np.random.default_rng(5)
    I0 = rng.normal(0.0, 30.0, m)
    I = I0.copy()
    for n in range(1, 301):
        I = internal_pi_update(np.zeros(m), K_p, T_i, dt, I, np.full(m, 1e3), np.full(m, 1e3), AT)[0]
        if n == 1:
            assert np.abs(I - I0).max() <= dt / T_i * np.abs(I0).max() * np.sqrt(m)
    np.testing.assert_allclose(I, P @ I0 + (1.0 - dt / T_i) ** 300 * (I0 - P @ I0), atol=1e-9)


def test_the_stage_projects_only_where_it_is_given_x_d(ipanema3):
    """CableForceControl.update: with x_d the integral part is internal; without x_d, or with
    internal_integral off, it is the printed (3.19) (the compiled period), the same numbers as before."""
    dt, m = 0.001, ipanema3.m
    theta = inverse_kinematics(ipanema3, X).q
    f_d = np.linspace(600.0, 1500.0, m)
    outs = {}
    on = CFCParams(internal_integral=True)
    for name, params, x_d in (("plain", CFCParams(), X), ("none", on, None), ("internal", on, X)):
        stage = CableForceControl(ipanema3, dt, params)
        stage.calibration.set_home(ipanema3, f_d)
        f = f_d + 40.0
        for _ in range(200):
            stage.update(f_d, f, theta, np.full(m, 100.0), np.full(m, 3000.0), x_d=x_d)
        outs[name] = stage.controller.pi.integrator.copy()
    np.testing.assert_array_equal(outs["plain"], outs["none"])
    AT = inverse_kinematics(ipanema3, X).AT
    assert np.abs(AT @ outs["plain"]).max() > 1.0
    assert np.abs(AT @ outs["internal"]).max() < 1e-9 * np.abs(outs["internal"]).max()


def test_internal_integral_is_validated():
    with pytest.raises(ValueError, match="internal_integral"):
        CFCParams(internal_integral="yes").validate()

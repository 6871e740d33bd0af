"""The compiled internal integral of the CFC (CFCParams.internal_integral) against its numpy
reference: the projector onto the internal forces (2.41) with and without held cables
(kernels.control.nullspace_projector_kernel: an orthonormal basis of the free columns' row space, against the
reference's 6x6 solve and pseudo-inverse), the PI period (3.19) with the integral on the internal
forces (internal_pi_kernel) on random errors, integrators and saturations, and the whole CFC
period (3.19)-(3.23) (cfc_internal_period) of the stage along a moving set-point, through
saturation, held cables, the clamping and a held PI. The two differ in the rounding of sums only:
equal to 1e-12 of the values' scale, the saturation flags equal."""
import numpy as np
import pytest
from poses import random_poses

from cdpr_control import kernels
from cdpr_control.control import cable_force_control as cfc
from cdpr_control.control.cable_force_control import CableForceControl, CFCParams
from cdpr_control.model import kinematics


def _AT(robot, x):
    return kinematics.inverse_kinematics(robot, x).AT


def test_the_internal_integral_laws_are_registered_with_their_references():
    for name, reference in (("nullspace_projector", cfc._nullspace_projector),
                            ("internal_pi_update", cfc._internal_pi_update),
                            ("cfc_internal_period", cfc._cfc_internal_period)):
        assert kernels.LAWS[name].reference is reference
    assert kernels.LAWS["cfc_internal_period"].compiled is kernels.compiled_cfc_internal_period


def test_projector_kernel_equals_the_reference_with_and_without_held_cables(robot):
    """Random poses, every number of held cables (with all m held: P = 0; with m - 6 or fewer free the
    free columns are independent: P = 0 too)."""
    rng = np.random.default_rng(23)
    m = robot.m
    counts = np.zeros(m + 1, dtype=int)
    for x in random_poses(robot, 60, rng):
        AT = _AT(robot, x)
        for n_held in range(m + 1):
            held = np.zeros(m, dtype=bool)
            held[rng.choice(m, n_held, replace=False)] = True
            fast = cfc.nullspace_projector.compiled(AT, held if n_held else None)
            ref = cfc._nullspace_projector(AT, held if n_held else None)
            np.testing.assert_allclose(fast, ref, rtol=0.0, atol=1e-12)
            np.testing.assert_allclose(AT @ fast, 0.0, atol=1e-9 * np.abs(AT).max())
            np.testing.assert_array_equal(fast[held], 0.0)
            counts[n_held] += 1
            assert np.trace(fast) == pytest.approx(max(m - 6 - n_held, 0), abs=1e-9)
    assert counts.min() == 60


def test_projector_kernel_falls_back_to_the_pseudo_inverse_where_A_T_is_rank_deficient(robot):
    """Two equal rows of A^T (rank 5): the Cholesky fails, the kernel takes the reference's
    pseudo-inverse (nullspace of dimension m - 5), also with a held cable."""
    AT = _AT(robot, robot.home).copy()
    AT[5] = AT[4]
    held = np.zeros(robot.m, dtype=bool)
    held[1] = True
    for h in (None, held):
        fast, ref = cfc.nullspace_projector.compiled(AT, h), cfc._nullspace_projector(AT, h)
        np.testing.assert_allclose(fast, ref, rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(AT @ fast, 0.0, atol=1e-9)
    assert np.trace(cfc.nullspace_projector.compiled(AT)) == pytest.approx(robot.m - 5)


def _held_at_first_try(e, K_p, T_i, dt, integrator, u_neg, u_pos, AT):
    """Whether the reference's first projected increment pushes a saturated cable further out (the
    re-projection with held cables runs), and whether the clamping scales the integrator."""
    P = cfc._nullspace_projector(AT)
    I = integrator - min(1.0, dt / T_i) * (integrator - P @ integrator)
    step = P @ (K_p * dt / T_i * e)
    u_free = K_p * e + I + step
    return bool(np.any(((u_free > u_pos) & (step > 0)) | ((u_free < -u_neg) & (step < 0))))


def test_internal_pi_kernel_equals_the_reference_on_random_errors_and_saturations(robot):
    """Random errors, integrators (with a part outside the nullspace, decaying), per-cable limits
    from tight to loose, per-cable gains and a scalar T_i = inf (no integration): the compiled period
    gives the reference's integrator and output to 1e-12 of their scale and the same saturation
    flags; the held re-projection, the clamping and the free case all occur many times."""
    rng = np.random.default_rng(29)
    m, dt = robot.m, 1e-3
    seen = {"held": 0, "free": 0, "clamped": 0, "saturated": 0}
    poses = random_poses(robot, 40, rng)
    for k in range(3000):
        AT = _AT(robot, poses[k % len(poses)])
        size = (2.0, 20.0, 300.0)[k % 3]                               # free, around the limits, far out
        e = rng.normal(0.0, size, m)
        integrator = rng.normal(0.0, 0.3 * size, m)
        u_neg, u_pos = rng.uniform(5.0, 150.0, m), rng.uniform(5.0, 150.0, m)
        K_p = rng.uniform(0.2, 1.5, m) if k % 2 else 0.85
        T_i = np.inf if k % 97 == 0 else rng.uniform(0.002, 0.2)     # dt / T_i up to 0.5: large steps
        args = (e, K_p, T_i, dt, integrator, u_neg, u_pos, AT)
        fast = cfc.internal_pi_update.compiled(*args)
        ref = cfc._internal_pi_update(*args)
        scale = max(1.0, np.abs(ref[0]).max(), np.abs(ref[2]).max())
        np.testing.assert_allclose(fast[0], ref[0], rtol=0.0, atol=1e-12 * scale)
        np.testing.assert_allclose(fast[2], ref[2], rtol=0.0, atol=1e-12 * scale)
        np.testing.assert_array_equal(fast[1], ref[1])
        pushed = _held_at_first_try(e, np.broadcast_to(K_p, m), T_i, dt, integrator, u_neg, u_pos, AT)
        seen["held" if pushed else "free"] += 1
        seen["clamped"] += bool(np.any(np.isclose(np.abs(ref[0]), np.where(ref[0] > 0, u_pos, u_neg), rtol=1e-12)))
        seen["saturated"] += bool(ref[1].any())
    assert min(seen.values()) > 100, seen


def test_internal_pi_kernel_passes_a_non_finite_error_on_as_the_reference(robot):
    """A NaN error (a broken sensor upstream): both give NaN in the same places (the stages around
    the CFC keep it from a drive), neither raises."""
    AT = _AT(robot, robot.home)
    e = np.full(robot.m, 10.0)
    e[2] = np.nan
    limits = np.full(robot.m, 100.0)
    fast = cfc.internal_pi_update.compiled(e, 0.85, 0.1, 1e-3, np.zeros(robot.m), limits, limits, AT)
    ref = cfc._internal_pi_update(e, 0.85, 0.1, 1e-3, np.zeros(robot.m), limits, limits, AT)
    for a, b in zip(fast, ref):
        np.testing.assert_array_equal(np.isnan(a) if a.dtype == float else a, np.isnan(b) if b.dtype == float else b)


@pytest.mark.parametrize("model", ["nonlinear", "linear"])
def test_cfc_internal_period_of_the_stage_equals_the_reference(robot, model):
    """CableForceControl.update with internal_integral and a moving x_d (the compiled law
    cfc_internal_period) against the same stage on the numpy reference: the PT1, the widened
    saturation near both limits, the internal PI through saturation, held cables and release, a
    feed-forward other than f_d, a held PI now and then, both stiffness models; Δq_CFC to 1e-12
    relative, the integrators and f_c,out to 1e-12 of their scale, the saturation flags equal."""
    rng = np.random.default_rng(31)
    f_min, f_max = robot.cable.f_min, robot.cable.f_max
    span = float(np.min(f_max - f_min))
    params = CFCParams(stiffness_model=model, F_sat_n=0.1 * span, F_sat_p=0.1 * span, widen_band=0.2 * span,
                       internal_integral=True)
    fast, ref = CableForceControl(robot, 1e-3, params), CableForceControl(robot, 1e-3, params)
    theta = kinematics.inverse_kinematics(robot, robot.home).q
    r = 0.02 * robot.frame_size[0]
    seen = np.zeros(2, dtype=int)
    for k in range(2000):
        x_d = robot.home + np.array([r * np.sin(k / 300.0), 0.0, r * (1.0 - np.cos(k / 300.0)), 0.0, 0.0, 0.0])
        f_d = f_min + (f_max - f_min) * (0.5 + 0.5 * np.sin(k / 150.0 + np.arange(robot.m)))
        f = f_d + 0.3 * span * np.sin(k / 40.0 + np.arange(robot.m)) + rng.normal(0.0, 0.02 * span, robot.m)
        f_ff = f_d + 3.0 if k % 3 else None
        for stage in (fast, ref):
            stage.controller.pi.hold = 700 <= k < 760
        dq = fast.update(f_d, f, theta, f_min, f_max, f_ff, x_d=x_d)
        with kernels.numpy_reference():
            dq_ref = ref.update(f_d, f, theta, f_min, f_max, f_ff, x_d=x_d)
        np.testing.assert_allclose(dq, dq_ref, rtol=1e-12, atol=1e-15)
        I, I_ref = fast.controller.pi.integrator, ref.controller.pi.integrator
        np.testing.assert_allclose(I, I_ref, rtol=0.0, atol=1e-12 * max(1.0, np.abs(I_ref).max()))
        f_out = ref.controller.f_out                 # (an f_c,out near 0 gets the rounding of its neighbours' sums)
        np.testing.assert_allclose(fast.controller.f_out, f_out, rtol=1e-12, atol=1e-12 * np.abs(f_out).max())
        np.testing.assert_array_equal(fast.controller.pi.saturated, ref.controller.pi.saturated)
        np.testing.assert_allclose(fast.controller.f_filtered, ref.controller.f_filtered, rtol=1e-12)
        sat = ref.controller.pi.saturated
        seen += sat.sum(), (~sat).sum()
    assert seen.min() > 1000                     # both regimes, many times

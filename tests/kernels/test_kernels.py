"""The compiled per-period kernels (cdpr_control.kernels) against the numpy reference.

Every kernel is the same computation as its numpy module; they differ only in the rounding of
sums (BLAS, fused multiply-add), so the comparisons use tolerances of a few 1e-12 relative.
"""
import contextlib
from dataclasses import replace

import numpy as np
import pytest
from poses import random_poses

from cdpr_control.model import cable, dynamics, kinematics
from cdpr_control import kernels
from cdpr_control.control.cable_force_control import CableForceControl, CFCParams, widened_saturation
from cdpr_control.control.loop import ControlLoop
from cdpr_control.model.forward_kinematics import CONVERGED, NON_FINITE, ForwardKinematics
from cdpr_control.model.friction import PulleyFriction, winch_force_from_sensor
from cdpr_control.control.joint_command import JointCommand
from cdpr_control.kernels import model as fk_kernels
from cdpr_control.control.pi_control import PIController


def test_the_kernels_are_enabled_and_numpy_reference_switches_them_off():
    assert kernels.ENABLED
    with kernels.numpy_reference():
        assert not kernels.ENABLED
    assert kernels.ENABLED


def test_a_law_runs_its_compiled_twin_unless_the_kernels_are_off(monkeypatch):
    """The one place that picks compiled code: each law of kernels.LAWS calls its twin while
    ENABLED and its reference under numpy_reference(), never the other."""
    import cdpr_control.control.cable_force_control  # noqa: F401  (registers the CFC's laws)
    assert {"inverse_kinematics", "cable_lengths", "measured_wrench", "platform_wrench", "cable_stiffness",
            "pi_update", "widened_saturation", "cfc_period"} <= set(kernels.LAWS)
    for name, law in kernels.LAWS.items():
        monkeypatch.setattr(law, "reference", lambda *a, _n=name: ("reference", _n, a))
        monkeypatch.setattr(law, "compiled", lambda *a, _n=name: ("compiled", _n, a))
    for name, law in kernels.LAWS.items():
        assert law(1, 2) == ("compiled", name, (1, 2))
        with kernels.numpy_reference():
            assert law(1, 2) == ("reference", name, (1, 2))


def test_the_model_laws_have_the_model_functions_as_references():
    assert kernels.LAWS["inverse_kinematics"].reference is kinematics.inverse_kinematics
    assert kernels.LAWS["platform_wrench"].reference is dynamics.platform_wrench
    assert kernels.LAWS["cable_stiffness"].reference is cable.stiffness


@pytest.mark.parametrize("pulleys", [True, False])
def test_inverse_kinematics_kernel_equals_the_reference(robot, pulleys):
    robot = robot if pulleys else replace(robot, swivelling_pulleys=False)
    rng = np.random.default_rng(11)
    for x in random_poses(robot, 100, rng):
        ref = kinematics.inverse_kinematics(robot, x)
        fast = kernels.inverse_kinematics(robot, x)
        for name, a, b in zip(ref._fields, fast, ref):
            assert np.shape(a) == np.shape(b), name
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14, err_msg=name)
        np.testing.assert_allclose(kernels.cable_lengths(robot, x), ref.q, rtol=1e-13, atol=0)
        f = rng.uniform(robot.cable.f_min, robot.cable.f_max)
        np.testing.assert_allclose(kernels.measured_wrench(robot, x, f), -ref.AT @ f, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("pulleys", [True, False])
def test_inverse_kinematics_fields_are_those_of_inverse_kinematics(robot, pulleys):
    """inverse_kinematics_fields: the same numbers as the full result, compiled and numpy."""
    robot = robot if pulleys else replace(robot, swivelling_pulleys=False)
    names = ("q", "beta", "gamma", "l_f", "kappa", "AT", "cT")
    for x in random_poses(robot, 20, np.random.default_rng(12)):
        for reference in (False, True):
            with kernels.numpy_reference() if reference else contextlib.nullcontext():
                ik = kernels.inverse_kinematics(robot, x)
                fields = kernels.inverse_kinematics_fields(robot, x, *names)
            for name, a in zip(names, fields):
                b = ik.c.T if name == "cT" else getattr(ik, name)
                assert a.flags.c_contiguous or reference, name
                np.testing.assert_array_equal(a, b, err_msg=name)


def test_inverse_kinematics_fields_serve_the_same_pose_again_and_only_it(robot):
    """The last result is reused for the same robot and pose (the stages of one period), never for
    another pose or robot."""
    x0, x1 = np.array(robot.home), robot.home + np.r_[0.01, 0.0, -0.02, 0.01, 0.0, 0.0]
    fixed = replace(robot, swivelling_pulleys=False)
    first, = kernels.inverse_kinematics_fields(robot, x0, "AT")
    again, = kernels.inverse_kinematics_fields(robot, x0.copy(), "AT")
    assert np.shares_memory(first, again)
    for r, x in ((robot, x1), (fixed, x1), (robot, x0)):
        AT, = kernels.inverse_kinematics_fields(r, x, "AT")
        np.testing.assert_array_equal(AT, kernels.inverse_kinematics(r, x).AT)
    assert not np.shares_memory(AT, first)


def test_inverse_kinematics_kernel_inside_the_pulley_circle(robot):
    """As the reference: no tangent from a platform point inside the pulley circle, q is NaN."""
    ik = kinematics.inverse_kinematics(robot, robot.home)
    # move the platform so that the anchor of cable 0 lies at r_p / 2 from the swivel axis
    R_A = kinematics.pulley_frames(robot)[0]
    bA = R_A.T @ (ik.Rb[0] + robot.home[:3] - robot.a[0])
    x = robot.home.copy()
    x[:3] -= R_A @ (bA - np.array([0.5 * robot.r_p[0], 0.0, 0.0]))
    ref, fast = kinematics.inverse_kinematics(robot, x), kernels.inverse_kinematics(robot, x)
    for name, a, b in zip(ref._fields, fast, ref):
        np.testing.assert_array_equal(np.isfinite(a), np.isfinite(b), err_msg=name)
        np.testing.assert_allclose(a[np.isfinite(a)], b[np.isfinite(b)], rtol=1e-12, atol=1e-12, err_msg=name)
    assert np.isnan(fast.q[0]) and np.isfinite(fast.q[1:]).all()


def test_platform_wrench_kernel_equals_the_reference(robot):
    rng = np.random.default_rng(12)
    loaded = robot.with_payload(0.3 * robot.platform.mass, (0.01, -0.02, 0.03))
    for r in (robot, loaded):
        for x in random_poses(r, 50, rng):
            xdot, xddot = rng.normal(size=6), rng.normal(size=6)
            np.testing.assert_allclose(kernels.platform_wrench(r, x, xdot, xddot),
                                       dynamics.platform_wrench(r, x, xdot, xddot), rtol=1e-12, atol=1e-11)


def _measurement(robot, rng, x_d):
    """Encoder lengths and forces of a platform held near x_d: the true pose within a few mm and
    mrad, forces within the limits, theta = IK(x) - dq(f) (3.7)."""
    x = x_d + np.r_[rng.uniform(-3e-3, 3e-3, 3), rng.uniform(-3e-3, 3e-3, 3)]
    f = rng.uniform(robot.cable.f_min, 0.5 * robot.cable.f_max)
    q = kinematics.inverse_kinematics(robot, x).q
    theta = q - cable.elongation_from_force(robot, f, cable.total_free_length(robot, q))
    return theta, f


def test_elastic_forward_kinematics_kernel_equals_the_reference(robot):
    """Consistent measurements (theta = IK(x) - dq(f)): same pose to 1e-12, same iterations and
    termination, with and without the IK of x_d given."""
    rng = np.random.default_rng(13)
    solver = ForwardKinematics(robot, xtol=1e-9, max_iterations=30)
    for x_d in random_poses(robot, 40, rng):
        theta, f = _measurement(robot, rng, x_d)
        results = [solver.elastic(theta, f, x_d, ik_d=kernels.inverse_kinematics(robot, x_d)),
                   solver.elastic(theta, f, x_d), solver.elastic(theta, f, x_d, ik_d=kernels.setpoint_ik(robot, x_d))]
        with kernels.numpy_reference():
            results += [solver.elastic(theta, f, x_d, ik_d=kinematics.inverse_kinematics(robot, x_d)),
                        solver.elastic(theta, f, x_d), solver.elastic(theta, f, x_d, ik_d=kernels.setpoint_ik(robot, x_d))]
        assert results[3].termination == CONVERGED
        for fast, ref in zip(results[:3], results[3:]):
            assert (fast.converged, fast.termination, fast.iterations) == (ref.converged, ref.termination,
                                                                           ref.iterations)
            np.testing.assert_allclose(fast.x, ref.x, rtol=0, atol=1e-12)
            np.testing.assert_allclose(fast.residual_norm, ref.residual_norm, rtol=1e-6, atol=1e-9)


def test_the_setpoint_ik_is_the_fields_of_the_ik_in_both_flavours(robot):
    """kernels.setpoint_ik (ControlLoop's IK of x_d, shared by its stages) holds the same numbers as
    the full IK, bit for bit in each flavour; compiled, as the C-contiguous float64 arrays the
    kernels take (a view with other strides would compile another specialization or copy)."""
    rng = np.random.default_rng(23)
    for x_d in random_poses(robot, 20, rng):
        for mode in (contextlib.nullcontext(), kernels.numpy_reference()):
            with mode:
                ik, full = kernels.setpoint_ik(robot, x_d), kernels.inverse_kinematics(robot, x_d)
            for a, b in ((ik.q, full.q), (ik.AT, full.AT), (ik.cT, full.c.T), (ik.c, full.c), (ik.beta, full.beta)):
                assert a.shape == b.shape and a.tobytes() == np.ascontiguousarray(b).tobytes()
        ik = kernels.setpoint_ik(robot, x_d)
        assert all(v.dtype == np.float64 and v.flags.c_contiguous for v in ik)
        # the FK's solution with it handed over is the one it finds taking the IK itself, bit for bit
        solver = ForwardKinematics(robot, xtol=1e-9, max_iterations=30)
        theta, f = _measurement(robot, rng, x_d)
        handed, own = solver.elastic(theta, f, x_d, ik_d=ik), solver.elastic(theta, f, x_d)
        assert handed.x.tobytes() == own.x.tobytes() and handed.iterations == own.iterations


def test_elastic_forward_kinematics_kernel_with_inconsistent_measurements(robot):
    """A start-up elongation dq0 that the pose cannot explain leaves a least-squares residual; at
    its minimum the last LM steps are rounding noise, so the two may take a different number of
    them, but both stop on a step below xtol at the same pose within xtol."""
    rng = np.random.default_rng(19)
    solver = ForwardKinematics(robot, xtol=1e-9, max_iterations=30)
    for x_d in random_poses(robot, 40, rng):
        theta, f = _measurement(robot, rng, x_d)
        dq0 = rng.uniform(0.0, 1e-4, robot.m)
        fast = solver.elastic(theta, f, x_d, dq0)
        with kernels.numpy_reference():
            ref = solver.elastic(theta, f, x_d, dq0)
        assert fast.termination == ref.termination == CONVERGED
        np.testing.assert_allclose(fast.x, ref.x, rtol=0, atol=solver.xtol)
        np.testing.assert_allclose(fast.residual_norm, ref.residual_norm, rtol=1e-9)


def test_elastic_forward_kinematics_kernel_stops_as_the_reference(robot):
    """The other terminations: iteration budget, non-finite measurements."""
    rng = np.random.default_rng(14)
    x_d = random_poses(robot, 1, rng)[0]
    theta, f = _measurement(robot, rng, x_d)
    for solver, args in ((ForwardKinematics(robot, max_iterations=1), (theta, f)),
                         (ForwardKinematics(robot), (np.full(robot.m, np.nan), f))):
        fast = solver.elastic(*args, x_d)
        with kernels.numpy_reference():
            ref = solver.elastic(*args, x_d)
        assert not ref.converged
        assert (fast.termination, fast.iterations) == (ref.termination, ref.iterations)
        np.testing.assert_allclose(fast.x, ref.x, rtol=0, atol=1e-12)
    assert fast.termination == NON_FINITE


def test_frozen_residual_jacobian_by_finite_differences(robot):
    """(dPsi/dx)^T of the compiled frozen-pulley residual (3.9) against central differences, and
    Psi against the numpy reference's residual."""
    rng = np.random.default_rng(15)
    solver = ForwardKinematics(robot)
    x_d = random_poses(robot, 1, rng)[0]
    ik_d = kinematics.inverse_kinematics(robot, x_d)
    k_l = rng.uniform(1e4, 1e5, robot.m)
    q_free = ik_d.l_f + rng.uniform(-1e-3, 1e-3, robot.m)
    cT = np.ascontiguousarray(ik_d.c.T)
    ref = solver._frozen_residual(cT, q_free, k_l)
    m = robot.m
    buffers = (np.empty((3, 3)), np.empty((3, 3, 3)), np.empty(3))

    def residual(x):
        res, JT = np.empty(m), np.empty((6, m))
        fk_kernels._frozen_residual(x, cT, np.ascontiguousarray(robot.b), q_free, k_l, res, JT, *buffers)
        return res, JT

    for x in x_d + rng.uniform(-0.01, 0.01, (5, 6)):
        res, JT = residual(x)
        res_ref, JT_ref = ref(x)
        np.testing.assert_allclose(res, res_ref, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(JT, JT_ref, rtol=1e-12, atol=1e-9)
        h = 1e-6
        for k in range(6):
            dx = np.zeros(6)
            dx[k] = h
            fd = (residual(x + dx)[0] - residual(x - dx)[0]) / (2 * h)
            np.testing.assert_allclose(JT[k], fd, rtol=1e-6, atol=1e-6 * np.abs(JT).max())


def test_cable_state_and_stiffness_kernels_equal_cdpr_control_cable(robot):
    rng = np.random.default_rng(16)
    d = kernels.robot_data(robot)
    f = np.r_[-5.0, 0.0, rng.uniform(0.0, robot.cable.f_max[0], robot.m - 2)]
    theta = rng.uniform(0.5, 3.0, robot.m)
    q_hat, k_l = fk_kernels.elastic_cable_state(theta, f, d.l_0, d.k0, d.k1, d.k2)
    dq = cable.elongation_from_force_and_winch_length(robot, f, theta)
    np.testing.assert_allclose(q_hat, theta + dq, rtol=1e-14)
    np.testing.assert_allclose(k_l, cable.stiffness(robot, f, cable.total_free_length(robot, theta + dq)), rtol=1e-14)
    np.testing.assert_allclose(kernels.cable_stiffness(robot, f, theta), cable.stiffness(robot, f, theta), rtol=1e-14)


def test_pi_kernel_equals_the_reference_through_saturation():
    """Integration, saturation with anti-windup and release, per-call widened limits, T_i = inf."""
    rng = np.random.default_rng(17)
    n = 6
    args = (n, rng.uniform(0.1, 2.0, n), np.r_[rng.uniform(0.05, 0.5, n - 1), np.inf], 1.0, 2.0, 1e-3)
    fast, ref = PIController(*args), PIController(*args)
    seen = np.zeros(2, dtype=int)
    for k in range(3000):
        e = np.sin(k / 300.0 + np.arange(n)) * 2.0 + 0.1 * rng.normal(size=n)
        limits = (rng.uniform(0.5, 3.0, n), rng.uniform(0.5, 3.0, n)) if k % 2 else (None, None)
        u = fast.update(e, *limits)
        with kernels.numpy_reference():
            u_ref = ref.update(e, *limits)
        np.testing.assert_allclose(u, u_ref, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(fast.integrator, ref.integrator, rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(fast.saturated, ref.saturated)
        seen += ref.saturated.sum(), (~ref.saturated).sum()
    assert seen.min() > 1000                         # both regimes, many times
    assert fast.update(np.ones(n), 0.5, 0.5).max() == 0.5             # scalar per-call limits


def test_widened_saturation_kernel_equals_the_reference(robot):
    p = CFCParams()
    f = np.linspace(robot.cable.f_min[0] - 10, robot.cable.f_max[0] + 10, robot.m)
    for ref, fast in zip(widened_saturation.reference(p, f, robot.cable.f_min, robot.cable.f_max),
                         widened_saturation.compiled(p, f, robot.cable.f_min, robot.cable.f_max)):
        np.testing.assert_allclose(fast, ref, rtol=1e-14)


@pytest.mark.parametrize("model", ["nonlinear", "linear"])
def test_cfc_period_kernel_equals_the_reference(robot, model):
    """CableForceControl's compiled period (the law cfc_period) against the numpy stages: the PT1,
    widened saturation near both limits, PI through saturation and release, a feed-forward other
    than f_d, a held integrator now and then, both stiffness models; equal to rounding."""
    rng = np.random.default_rng(19)
    f_min, f_max = robot.cable.f_min, robot.cable.f_max
    span = float(np.min(f_max - f_min))
    params = CFCParams(stiffness_model=model, F_sat_n=0.2 * span, F_sat_p=0.2 * span, widen_band=0.2 * span)
    fast, ref = CableForceControl(robot, 1e-3, params), CableForceControl(robot, 1e-3, params)
    theta = kinematics.inverse_kinematics(robot, robot.home).q
    seen = np.zeros(2, dtype=int)
    for k in range(2000):
        f_d = f_min + (f_max - f_min) * (0.5 + 0.5 * np.sin(k / 150.0 + np.arange(robot.m)))
        f = f_d + 0.2 * span * np.sin(k / 40.0) + rng.normal(0.0, 0.02 * span, robot.m)
        f_ff = f_d + 3.0 if k % 3 else None
        for stage in (fast, ref):
            stage.controller.pi.hold = 700 <= k < 800
        dq = fast.update(f_d, f, theta, f_min, f_max, f_ff)
        with kernels.numpy_reference():
            dq_ref = ref.update(f_d, f, theta, f_min, f_max, f_ff)
        np.testing.assert_allclose(dq, dq_ref, rtol=1e-12, atol=1e-15)
        for name in ("f_out",):
            np.testing.assert_allclose(getattr(fast.controller, name), getattr(ref.controller, name), rtol=1e-12)
        np.testing.assert_allclose(fast.controller.pi.integrator, ref.controller.pi.integrator, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(fast.controller.pi.saturated, ref.controller.pi.saturated)
        np.testing.assert_allclose(fast.controller.f_filtered, ref.controller.f_filtered, rtol=1e-12)
        seen += ref.controller.pi.saturated.sum(), (~ref.controller.pi.saturated).sum()
    assert seen.min() > 1000                         # both regimes, many times


def test_joint_command_kernel_equals_the_reference(robot):
    """JointCommand.update compiled (kernels.joint_command_step) against the numpy reference:
    following, rate-limited after a jump, offsets and Δq_CFC, a non-finite target and holds
    (braking)."""
    fast, ref = JointCommand(robot, 1e-3), JointCommand(robot, 1e-3)
    theta = kinematics.inverse_kinematics(robot, robot.home).q
    fast.reset(theta), ref.reset(theta)
    counts = np.zeros(3, dtype=int)                  # held, rate-limited, free periods
    for k in range(800):
        x_d = robot.home + 0.02 * np.sin(k / 50.0) * np.array([1.0, 0.5, 0.3, 0.05, 0.02, 0.01])
        x_d[2] += 0.05 * (k >= 100)                  # a jump: rate-limited for a while
        dq = np.full(robot.m, 1e-4 * np.cos(k / 30.0))
        if 400 <= k < 420:
            dq[k % robot.m] = np.nan                 # a target outside the model: held
        offsets = [np.full(6, 1e-4)] if k % 2 else []
        hold = 600 <= k < 650
        theta_d = fast.update(x_d, offsets, dq if k % 5 else None, hold=hold)
        with kernels.numpy_reference():
            theta_ref = ref.update(x_d, offsets, dq if k % 5 else None, hold=hold)
        np.testing.assert_allclose(theta_d, theta_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fast.velocity, ref.velocity, rtol=0, atol=1e-9)
        assert fast.held == ref.held
        limited = np.abs(ref.velocity).max() >= ref.v_max * (1 - 1e-12)
        counts += ref.held, not ref.held and limited, not ref.held and not limited
    assert counts.min() >= 10


def test_friction_compiled_with_changing_wrap_angles_equals_numpy(robot):
    """The controller's friction model sees a new beta every period: the compiled tables of the
    swivelling pulley (friction.last_pulley_tables) and Dahl step against PulleyFriction's numpy,
    state included, through direction changes and standstill."""
    rng = np.random.default_rng(18)
    ik = kinematics.inverse_kinematics(robot, robot.home)
    plain = PulleyFriction.from_robot(robot, ik.q, 1e-7)
    fast = PulleyFriction.from_robot(robot, ik.q, 1e-7)
    theta = ik.q.copy()
    for k in range(500):
        v = 0.05 * np.sin(k / 40.0 + np.arange(robot.m)) * (k % 100 > 10)
        theta = theta + v * 1e-3
        beta = ik.beta + 0.1 * np.sin(k / 70.0)
        F_s = rng.uniform(50.0, 200.0, robot.m)
        f_w = winch_force_from_sensor(F_s, robot.sensor.beta_1)
        np.testing.assert_allclose(kernels.friction_platform_force(fast, f_w, theta, v, beta),
                                   plain.platform_force(F_s, theta, v, beta), rtol=1e-12)
        np.testing.assert_allclose(fast.dahl.state, plain.dahl.state, rtol=1e-12, atol=1e-12)
    assert np.ptp(plain.dahl.state[0]) == 2.0                     # both directions seen


def test_control_loop_compiled_equals_numpy_reference_in_closed_loop(robot):
    """The whole loop (Fig. 3.4) around the simulator for 0.3 s on a circle: the compiled loop
    and the numpy reference loop command the same cable lengths."""
    from cdpr_sim.simulator import SimConfig, Simulator
    from cdpr_sim.startup import startup_state

    runs = []
    for compiled in (True, False):
        x0, theta0, offset = startup_state(robot, robot.home, 0.0, calibrate_home=True)
        loop = ControlLoop(robot, 1e-3)
        rows = []
        with Simulator(robot, SimConfig(), x0=x0, theta0=theta0, encoder_offset=offset) as sim:
            out = sim.output
            for k in range(300):
                w = 2 * np.pi * 0.5 * k * 1e-3
                x_d = robot.home + 0.01 * np.array([np.sin(w), 0, 1 - np.cos(w), 0, 0, 0])
                xdot = 0.01 * np.pi * np.array([np.cos(w), 0, np.sin(w), 0, 0, 0])
                xddot = 0.01 * np.pi ** 2 * np.array([-np.sin(w), 0, np.cos(w), 0, 0, 0])
                if compiled:
                    state = loop.step(out.t, x_d, xdot, xddot, out.theta, out.thetadot, out.F_s)
                else:
                    with kernels.numpy_reference():
                        state = loop.step(out.t, x_d, xdot, xddot, out.theta, out.thetadot, out.F_s)
                rows.append((state.theta_d, state.x, state.f_d, state.dq_cfc, state.x_ospc))
                out = sim.step(state.theta_d)
        runs.append([np.array(r) for r in zip(*rows)])
    (theta_d, x, f_d, dq, x_ospc), (theta_d_ref, x_ref, f_d_ref, dq_ref, x_ospc_ref) = runs
    np.testing.assert_allclose(theta_d, theta_d_ref, rtol=0, atol=1e-10)           # m
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-10)                       # m, rad
    np.testing.assert_allclose(f_d, f_d_ref, rtol=0, atol=1e-6)                    # N
    np.testing.assert_allclose(dq, dq_ref, rtol=0, atol=1e-10)
    np.testing.assert_allclose(x_ospc, x_ospc_ref, rtol=0, atol=1e-12)


def test_all_finite_equals_numpy_also_where_the_sum_overflows():
    from cdpr_control.control.safety import all_finite
    for v in ([1.0, -2.0, 3.0], [1.0, np.nan, 0.0], [np.inf, 1.0], [np.inf, -np.inf], [1e308, 1e308, -1.0],
              np.full(6, -1.7e308), np.zeros(6), [1e308, np.nan]):
        assert all_finite(v) == bool(np.isfinite(v).all()), v


def test_smith_predictor_kernel_equals_the_numpy_update():
    """WrenchSetpoint.update_filtered (compiled) against update with LowPass.update: the same
    numbers, through saturation, a known wrench, a delay change and a reset."""
    from cdpr_control.control.filters import LowPass
    from cdpr_control.control.wrench_setpoint import WrenchSetpoint

    rng = np.random.default_rng(5)
    pairs = [(WrenchSetpoint(0.005, 1e-3), LowPass(0.02, 1e-3)) for _ in range(2)]
    w_max = np.array([3.0, 3.0, 3.0, 0.5, 0.5, 0.5])
    for k in range(400):
        w, w_dyn = rng.normal(scale=4.0, size=(2, 6))
        known = None if k % 3 else rng.normal(size=6)
        if k == 150:
            for smith, _ in pairs:
                smith.set_delay(0.012)
        if k == 300:
            for smith, _ in pairs:
                smith.reset(w_dyn)
        (s0, f0), (s1, f1) = pairs
        reference = s0.update(w, w_dyn, w_max, f0.update, known)
        np.testing.assert_array_equal(s1.update_filtered(w, w_dyn, w_max, f1, known), reference)
        np.testing.assert_array_equal(f1.y, f0.y)

"""Online load identification (4.4) and load compensation (4.5)-(4.6), thesis section 4.1.2-4.1.3.

Library: the mass estimate and its guard, the moving average, the compliance against the static
equilibrium of the elastic cable model, the centre of gravity from the torque part, the payload
wrench against (2.33). Closed loop (in process, the simulator's plant as it is in this tree): payload
steps at standstill on the IPAnema 3 at r = [-1, -1, 0.5] m (one step of 32 kg on and off; the full
16 x 8 kg experiment is ``cdpr identify load-steps``) and on the Mini; a live disable and a guarded
estimate without a jump in θ_d.
"""
from dataclasses import replace

import numpy as np
import pytest

from cdpr_control.model import cable
from cdpr_control.model.dynamics import gravity_wrench, platform_wrench
from cdpr_control.model.forward_kinematics import ForwardKinematics
from cdpr_control.model.kinematics import inverse_kinematics, rotation_matrix
from cdpr_control.control.load_compensation import (LoadCompensation, LoadCompensationParams, MovingAverage,
    cable_stiffness_model, compensating_wrench, compliance, load_offset, mass_estimate, payload_wrench,
    secant_offset, SettlementModel)
from cdpr_control.model.robot import load_robot
from cdpr_control.model.stiffness import operational_stiffness

IPANEMA3 = load_robot("ipanema3")
# The closed-loop tests run on the mismatched plant (the estimate tared at the start, empty), except
# the sag cut: x_d,LC is a feed-forward of the cable model, so the plant's cable stiffness (8-15 %
# off) and its cable settlement under load (a lasting elongation of tens of mm after 128 kg, section
# 4.1.3) stay in the error; the >= 90 % of the sag it removes is a property of the model, measured
# on the nominal plant (docs/load_compensation.md gives the figures on both plants). On the
# mismatched plant the >= 90 % needs the identified cable and settlement (the last tests).
PLANT = "mismatched"
MINI = load_robot("ipanema3_mini")
POSE = np.r_[-1.0, -1.0, 0.5, 0.0, 0.0, 0.0]            # section 4.1.3
G = 9.81


def test_mass_estimate_4_4_static_accelerated_and_guarded():
    m = 40.0
    for a_z in (0.0, 2.0, -3.0):                          # w_z = m (g_z - a_z), the cables' share
        assert mass_estimate(m * (-G - a_z), a_z, -G, 1.0) == pytest.approx(m)
    assert mass_estimate(m * (-G + 9.5), -9.5, -G, 1.0) is None          # |a - g| = 0.31 < guard
    assert mass_estimate(float("nan"), 0.0, -G, 1.0) is None


def test_moving_average_starts_at_first_sample_and_changes_window_without_jump():
    ma = MovingAverage(0.01, 0.001)
    assert ma.n == 10 and ma.update(5.0)[0] == 5.0
    for k in range(10):
        ma.update(float(k))
    assert ma.mean[0] == pytest.approx(4.5)
    ma.set_window(0.02)
    assert ma.n == 20 and ma.mean[0] == pytest.approx(4.5)


def _equilibrium(robot, x, f0):
    """Unstretched lengths that hold the platform at x under the cable forces f0."""
    from cdpr_sim.simulator import pretension_lengths

    return pretension_lengths(robot, x, f0)


@pytest.mark.parametrize("robot, m_c", [(IPANEMA3, 2.0), (MINI, 0.05)])
def test_load_offset_4_6_equals_the_sag_of_the_elastic_equilibrium(robot, m_c):
    """C_x w_c (4.5)-(4.6) with the tangent cable stiffness is the displacement the elastic cables
    allow when m_c is added (operational-space FK (2.36) as the static equilibrium)."""
    from cdpr_sim.startup import startup_forces

    x = robot.home if robot is MINI else POSE
    f0 = startup_forces(robot, x, 0.0)
    theta = _equilibrium(robot, x, f0)
    fk = ForwardKinematics(robot)
    w_loaded = gravity_wrench(robot.with_payload(m_c), x)
    loaded = fk.operational_space(theta, x, w=w_loaded)
    assert loaded.converged
    sag = loaded.x - x
    ik = inverse_kinematics(robot, loaded.x)
    f1 = cable.force_from_elongation(robot, ik.q - theta, cable.total_free_length(robot, ik.q))
    ik_x = inverse_kinematics(robot, x)
    C_x = compliance(ik_x, f1, cable_stiffness_model(robot, ik_x, f1, "nonlinear"))
    x_lc = load_offset(C_x, m_c, robot.gravity)
    assert x_lc[2] > 0.0 > sag[2]
    np.testing.assert_allclose(x_lc[:3], -sag[:3], atol=0.03 * abs(sag[2]))


def _ik_only_state(robot, x, m, command=None):
    """Static equilibrium of IK-only control (θ = IK(command) - Δq_0 of the home calibration)
    carrying a payload m: (pose, forces at the platform)."""
    from cdpr_sim.simulator import home_calibration_offset
    from cdpr_sim.startup import startup_forces

    dq_0 = home_calibration_offset(robot, startup_forces(robot, robot.home, 0.0))
    theta = inverse_kinematics(robot, x if command is None else command).q - dq_0
    result = ForwardKinematics(robot).operational_space(theta, x, w=gravity_wrench(robot.with_payload(m), x))
    assert result.converged
    ik = inverse_kinematics(robot, result.x)
    return result.x, cable.force_from_elongation(robot, ik.q - theta, cable.total_free_length(robot, ik.q))


def test_secant_offset_is_the_command_that_holds_128_kg_at_the_set_point():
    """IK-only control at r = [-1, -1, 0.5] m (section 4.1.3) with 128 kg: the command x_d + c that
    puts the loaded platform back where it stood unloaded, found by iterating the elastic
    equilibrium (FK (2.36)), against secant_offset from the compensated state's forces. The tangent
    C_x w_c (4.6) at the same forces misses it by about 10 % (progressive cables, two of them slack,
    and K_g, which does not act while the platform stays put)."""
    x = POSE
    x_0, f_0 = _ik_only_state(IPANEMA3, x, 0.0)
    command = x.copy()
    for _ in range(30):
        command -= _ik_only_state(IPANEMA3, x, 128.0, command)[0] - x_0
    _, f = _ik_only_state(IPANEMA3, x, 128.0, command)
    c_exact = command - x                                     # small rotations: Kardan = twist here
    assert np.sum(f < 1.0) >= 2                               # lower cables slack under the payload
    ik = inverse_kinematics(IPANEMA3, x)
    w_c = compensating_wrench(128.0, IPANEMA3.gravity)
    c = secant_offset(IPANEMA3, ik, f, w_c, f_ref=f_0)
    np.testing.assert_allclose(c[:3], c_exact[:3], atol=0.03 * c_exact[2])
    np.testing.assert_allclose(c[3:], c_exact[3:], atol=0.1 * np.abs(c_exact[3:]).max())
    tangent = compliance(ik, f, cable_stiffness_model(IPANEMA3, ik, f, "nonlinear", 20.0)) @ w_c
    assert abs(tangent[2] - c_exact[2]) > 0.07 * c_exact[2]
    # no payload, no offset; no tensed cable, or one that cannot carry w_c, raises
    np.testing.assert_allclose(secant_offset(IPANEMA3, ik, f_0, np.zeros(6), f_ref=f_0), 0.0, atol=1e-12)
    with pytest.raises(np.linalg.LinAlgError):
        secant_offset(IPANEMA3, ik, np.zeros(8), w_c)
    with pytest.raises(np.linalg.LinAlgError):
        secant_offset(IPANEMA3, ik, np.r_[f[:1], np.zeros(7)], w_c)


def test_secant_offset_with_four_slack_cables_is_the_command_that_holds_the_mini_payload():
    """The Mini under IK-only control: its lower cables (5 N) go slack under half its static capacity
    at home and the platform hangs on the four upper ones, so K_c has rank 4. The minimum-norm
    secant offset still gives the command that puts the platform back (this raised before, and the
    load compensation kept its first offset: no sag cut on the Mini)."""
    x, m = MINI.home, 4.4
    x_0, f_0 = _ik_only_state(MINI, x, 0.0)
    command = x.copy()
    for _ in range(30):
        command -= _ik_only_state(MINI, x, m, command)[0] - x_0
    x_c, f = _ik_only_state(MINI, x, m, command)
    c_exact = command - x
    assert np.sum(f < 0.2 * MINI.cable.f_min) == 4
    ik = inverse_kinematics(MINI, x)
    c = secant_offset(MINI, ik, f, compensating_wrench(m, MINI.gravity), f_ref=f_0)
    assert c[2] == pytest.approx(c_exact[2], rel=0.02)
    # the command x + c holds the loaded platform where it stood unloaded, to 2 % of the sag
    x_held, _ = _ik_only_state(MINI, x, m, x + c)
    sag = _ik_only_state(MINI, x, m)[0][2] - x_0[2]
    assert abs(x_held[2] - x_0[2]) < 0.02 * abs(sag)


def test_secant_offset_shortens_the_cables_by_their_settlement():
    """Cable settlement (section 4.1.3) s = A c0 of a pose offset c0 and no payload: the command
    must shorten each cable by s, so the secant offset is c0 (the forces stay those of the state)."""
    x_0, f_0 = _ik_only_state(IPANEMA3, POSE, 0.0)
    ik = inverse_kinematics(IPANEMA3, POSE)
    c0 = np.r_[0.0, 0.0, 0.004, 0.0, 0.0, 0.0]
    s = ik.AT.T @ c0
    c = secant_offset(IPANEMA3, ik, f_0, np.zeros(6), f_ref=f_0, settlement=s)
    np.testing.assert_allclose(c, c0, atol=1e-3 * 0.004)


def test_settlement_model_grows_towards_its_target_and_never_shrinks():
    """s_i -> ratio l_t (f_i - f_settled) / k0 with time constant T; lower forces leave it."""
    model = SettlementModel(MINI, 1e-3, ratio=0.3, T=0.5)
    f0, l_t = np.full(MINI.m, 20.0), np.full(MINI.m, 1.5)
    model.reset(f0)
    for _ in range(5000):                                   # 10 T
        model.update(f0 + 10.0, l_t)
    np.testing.assert_allclose(model.s, 0.3 * 1.5 * 10.0 / MINI.cable.k0, rtol=1e-4)
    s = model.s.copy()
    model.update(f0, l_t)
    np.testing.assert_array_equal(model.s, s)
    model.set_params(0.0, 0.5)                              # off: held
    np.testing.assert_array_equal(model.update(f0 + 50.0, l_t), s)


def test_slack_cables_have_no_stiffness_whatever_the_noise_on_their_force():
    """A slack cable read at a few newtons (sensor noise) must not count as fully stiff in K_l."""
    ik = inverse_kinematics(IPANEMA3, POSE)
    f = np.r_[np.full(6, 800.0), 3.0, -2.0]
    k = cable_stiffness_model(IPANEMA3, ik, f, "nonlinear", f_slack=20.0)
    k_full = cable_stiffness_model(IPANEMA3, ik, f, "nonlinear")
    np.testing.assert_allclose(k[:6], k_full[:6])
    assert k[6] == pytest.approx(0.15 * k_full[6]) and k[7] == 0.0


def test_tare_removes_the_sensor_offset_from_the_estimate():
    """A force offset reads as payload; the tare at a known state (empty) removes it, and a later
    payload is then identified on top; no tare while the estimate is held."""
    lc = LoadCompensation(IPANEMA3, 1e-3, LoadCompensationParams(tare_at_start=True))
    empty, _ = _forces(IPANEMA3, POSE, np.zeros(6), np.zeros(6), 0.0, np.zeros(3))
    loaded, _ = _forces(IPANEMA3, POSE, np.zeros(6), np.zeros(6), 30.0, np.zeros(3))
    offset = np.r_[np.full(4, 10.0), np.full(4, -10.0)]      # 10 N per sensor (0.25 % of 4000 N)
    lc.update(POSE, np.zeros(6), np.zeros(6), empty + offset)
    assert abs(lc.m_c) > 1.5                                  # the offset reads as kilograms
    for _ in range(300):
        lc.update(POSE, np.zeros(6), np.zeros(6), empty + offset)
    assert lc.tared and lc.m_c == pytest.approx(0.0, abs=1e-9)
    for _ in range(300):
        lc.update(POSE, np.zeros(6), np.zeros(6), loaded + offset)
    assert lc.m_c == pytest.approx(30.0, rel=0.02)
    lc.guarded = True
    assert lc.tare(0.0) is None and lc.m_c == pytest.approx(30.0, rel=0.02)


def test_compliance_is_the_inverse_of_the_operational_stiffness_and_linear_model_differs():
    ik = inverse_kinematics(IPANEMA3, POSE)
    f = np.full(IPANEMA3.m, 800.0)
    k_n = cable_stiffness_model(IPANEMA3, ik, f, "nonlinear")
    k_l = cable_stiffness_model(IPANEMA3, ik, f, "linear")
    np.testing.assert_allclose(compliance(ik, f, k_n) @ operational_stiffness(ik, f, k_n), np.eye(6), atol=1e-9)
    assert not np.allclose(k_n, k_l)
    with pytest.raises(ValueError):
        cable_stiffness_model(IPANEMA3, ik, f, "spline")


def test_payload_wrench_is_the_difference_of_the_platform_wrench_2_33():
    rng = np.random.default_rng(1)
    x, xdot, xddot = POSE + np.r_[0, 0, 0, 0.1, -0.05, 0.2], rng.normal(size=6), rng.normal(size=6)
    cog = np.array([0.1, -0.05, 0.3])
    expected = (platform_wrench(IPANEMA3.with_payload(12.0, cog), x, xdot, xddot)
                - platform_wrench(IPANEMA3, x, xdot, xddot))
    np.testing.assert_allclose(payload_wrench(IPANEMA3, x, xdot, xddot, 12.0, cog), expected, atol=1e-9)


def test_payload_wrench_scalar_math_equals_the_numpy_formula():
    """payload_wrench is scalar math (it runs every period): the numpy form of its equation, up to
    the rounding of the sums."""
    rng = np.random.default_rng(2)
    for _ in range(200):
        x, xdot, xddot = rng.normal(size=(3, 6))
        cog, mass = rng.normal(scale=0.2, size=3), rng.uniform(0.0, 50.0)
        c = rotation_matrix(x[3:]) @ cog
        a_c = xddot[:3] + np.cross(xddot[3:], c) + np.cross(xdot[3:], np.cross(xdot[3:], c))
        f = mass * (IPANEMA3.gravity - a_c)
        w = payload_wrench(IPANEMA3, x, xdot, xddot, mass, tuple(cog))
        np.testing.assert_allclose(w, np.r_[f, np.cross(c, f)], rtol=1e-12, atol=1e-12 * mass * (1.0 + np.abs(a_c).max()))


def _forces(robot, x, xdot, xddot, m_c, cog):
    """Cable forces (QP distribution (3.27), A^T f = -w) that carry the platform and a payload."""
    from cdpr_control.force_distribution import ForceDistributor

    w = platform_wrench(robot, x, xdot, xddot) + payload_wrench(robot, x, xdot, xddot, m_c, cog)
    AT = inverse_kinematics(robot, x).AT
    c = robot.cable
    result = ForceDistributor(robot.m, c.f_min, c.f_max, method="qp").solve(AT, w, 1e-3)
    np.testing.assert_allclose(AT @ result.f, -w, atol=1e-6)
    return result.f, AT


def test_identifies_mass_and_the_centre_of_gravity_across_the_force():
    """At standstill the force is vertical: c_x, c_y are identified, c_z (along f) stays zero."""
    lc = LoadCompensation(IPANEMA3, 1e-3, LoadCompensationParams(enabled=False))
    cog = np.array([0.08, -0.05, 0.3])
    f, _ = _forces(IPANEMA3, POSE, np.zeros(6), np.zeros(6), 30.0, cog)
    for _ in range(300):
        lc.update(POSE, np.zeros(6), np.zeros(6), f)
    assert lc.m_c == pytest.approx(30.0, rel=1e-9) and not lc.guarded
    np.testing.assert_allclose(lc.cog, [0.08, -0.05, 0.0], atol=1e-6)


def test_guarded_estimate_holds_without_nan_and_disabled_output_is_zero():
    p = LoadCompensationParams(time_shift=0.0, T_output=0.0)
    lc = LoadCompensation(IPANEMA3, 1e-3, p)
    rest, _ = _forces(IPANEMA3, POSE, np.zeros(6), np.zeros(6), 20.0, np.zeros(3))
    for _ in range(1000):
        x_lc = lc.update(POSE, np.zeros(6), np.zeros(6), rest)
    m_before, x_before = lc.m_c, x_lc.copy()
    falling = np.r_[0.0, 0.0, -9.5, 0.0, 0.0, 0.0]           # |ẍ_z - g| = 0.31 m/s² < accel_guard
    f, _ = _forces(IPANEMA3, POSE, np.zeros(6), falling, 20.0, np.zeros(3))
    noise = np.random.default_rng(0).normal(0, 5, (500, IPANEMA3.m))
    for k in range(500):
        x_lc = lc.update(POSE, np.zeros(6), falling, f + noise[k])
        assert np.all(np.isfinite(x_lc)) and abs(lc.m_c - m_before) < 0.5
        # the guard acts on the window mean of ẍ_z (ratio of means), so it engages within the window
        assert lc.guarded or k < 240
    # the mass is held; C_x follows the lower forces of the falling platform (a few % softer)
    assert x_lc[2] == pytest.approx(x_before[2], rel=0.05)
    assert x_before[2] > 0.0
    lc.set_params(LoadCompensationParams(enabled=False))
    assert np.all(lc.update(POSE, np.zeros(6), np.zeros(6), rest) == 0.0)
    lc.update(POSE, np.zeros(6), np.zeros(6), np.full(IPANEMA3.m, np.nan))     # invalid: held, finite
    assert lc.guarded and np.isfinite(lc.m_c)


def test_rate_limit_bounds_the_output_step():
    p = LoadCompensationParams(time_shift=0.0, T_filter=0.0, T_output=0.0, v_max=0.01)
    lc = LoadCompensation(IPANEMA3, 1e-3, p)
    f, _ = _forces(IPANEMA3, POSE, np.zeros(6), np.zeros(6), 100.0, np.zeros(3))
    x = [lc.update(POSE, np.zeros(6), np.zeros(6), f) for _ in range(50)]
    steps = np.abs(np.diff(np.array(x)[:, :3], axis=0))
    assert steps.max() <= 0.01 * 1e-3 + 1e-15 and lc.rate_limited[2]


# --- closed loop (in process, simulator) ------------------------------------------------------

def _steps(robot, config, position, step_mass, steps=1, dwell=5.0, plant=PLANT, **kwargs):
    from cdpr_tools.identify import load_steps

    run = load_steps.payload_steps(robot, config, position=position, step_mass=step_mass, steps=steps, dwell=dwell,
                                   plant=plant, **kwargs)
    return run, load_steps.step_summary(run, dwell, 0.5)


def test_payload_steps_at_standstill_sag_cut_by_90_percent_up_to_128_kg():
    """Section 4.1.3 (Fig. 4.6) on the IPAnema 3 at r = [-1, -1, 0.5] m, shortened to two steps of
    64 kg (each put on over 1.5 s) up to the thesis' 128 kg: IK-only sags (mm/kg in
    docs/load_compensation.md), IK-only + LC cuts the static sag by >= 90 % at 64 and at 128 kg.
    Nominal plant: the cut is the cable model's (see PLANT)."""
    from cdpr_tools.identify.load_steps import sag_per_kg

    kwargs = dict(step_mass=64.0, steps=2, dwell=4.0, ramp=1.5, down=False, plant="nominal")
    ik, s_ik = _steps(IPANEMA3, "ik", POSE[:3], **kwargs)
    lc, s_lc = _steps(IPANEMA3, "ik_lc", POSE[:3], **kwargs)
    assert sag_per_kg(s_ik) > 0.3
    for a, b in zip(s_ik["steps"], s_lc["steps"]):
        sag_ik = a["z_error_mm"] - s_ik["unloaded_z_error_mm"]
        sag_lc = b["z_error_mm"] - s_lc["unloaded_z_error_mm"]
        assert abs(sag_lc) <= 0.1 * abs(sag_ik), (a["payload_kg"], sag_ik, sag_lc)
    assert s_lc["steps"][-1]["payload_kg"] == 128.0
    assert np.all(np.isfinite(lc.theta_d)) and np.all(np.isfinite(lc.x_lc))


@pytest.mark.parametrize("plant, cut", [("mismatched", 0.85), ("nominal", 0.90)])
def test_shipped_settlement_model_cuts_the_ik_lc_sag_on_both_plants(plant, cut):
    """The IPAnema 3's shipped load compensation (its settlement model, ratio 0.15 from the thesis'
    9.2 mm, params/ipanema3.yaml) under IK-only at home with 40.4 kg (the sweep's pose #0 at 25 %
    of its dynamic capacity): the sag cut is within issue 25's band on the settling mismatched
    plant (seed 1; without the model 81 %) and on the nominal plant, which does not settle (the
    model over-compensates there, by less than the band)."""
    from cdpr_control.control.params import shipped_configuration

    shipped = shipped_configuration(IPANEMA3).load_compensation
    assert shipped.settlement_ratio > 0.0
    kwargs = dict(step_mass=40.4, steps=1, dwell=4.0, ramp=0.3, down=False, plant=plant)
    _, s_ik = _steps(IPANEMA3, "ik", IPANEMA3.home[:3], **kwargs)
    lc, s_lc = _steps(IPANEMA3, "ik_lc", IPANEMA3.home[:3], lc_params=shipped, **kwargs)
    sag_ik = s_ik["steps"][0]["z_error_mm"] - s_ik["unloaded_z_error_mm"]
    sag_lc = s_lc["steps"][0]["z_error_mm"] - s_lc["unloaded_z_error_mm"]
    assert sag_ik < -15.0                                   # the platform sinks by about 21-26 mm
    assert abs(sag_lc) <= (1.0 - cut) * abs(sag_ik), (sag_ik, sag_lc)
    assert np.all(np.isfinite(lc.theta_d)) and np.all(np.isfinite(lc.x_lc))


@pytest.mark.parametrize("robot, position, step_mass", [(IPANEMA3, (-1.0, -1.0, 0.5), 32.0),
                                                        (MINI, (0.0, 0.0, 0.0), 1.0)])
def test_estimate_within_3_percent_1s_after_each_step_on_the_mismatched_plant(robot, position, step_mass):
    """One step on and off at standstill, IK-only + LC, on the mismatched plant with the estimate
    tared at the start (empty): 0.7 .. 1.0 s after the start of each step (mean) and at its end
    (mean over the last 0.3 s) the estimate is within 3 % of the payload (of the step for the
    step back to zero). Without the tare the sensors' offsets read as payload (a few tenths of a
    kilogram on this plant seed)."""
    dwell = 3.0
    lc, s_lc = _steps(robot, "ik_lc", position, step_mass, dwell=dwell)
    n_rest, n_dwell = 500, int(round(dwell / 1e-3))
    for j, row in enumerate(s_lc["steps"]):
        start = n_rest + j * n_dwell
        payload = row["payload_kg"]
        scale = max(payload, step_mass)
        assert abs(row["estimate_kg"] - payload) <= 0.03 * scale, (payload, row["estimate_kg"])
        early = lc.m_c[start + 700:start + 1000].mean()
        assert abs(early - payload) <= 0.03 * scale, (payload, early)
    assert np.all(np.isfinite(lc.theta_d)) and np.all(np.isfinite(lc.x_lc))


def test_disabling_live_does_not_jump_the_command():
    """Disabled live under 64 kg, x_d,LC leaves through the joint command's ramp: no θ_d step."""
    from cdpr_control.control.load_compensation import LoadCompensationStage
    from cdpr_sim.closed_loop import hold, run
    from cdpr_tools.identify.load_steps import loop_params

    stage = LoadCompensationStage(MINI, 1e-3, LoadCompensationParams())

    def schedule(k, loop, sim):
        if k == 100:
            sim.set_payload(1.0)
        if k == 1500:
            stage.compensation.set_params(LoadCompensationParams(enabled=False))

    # the force watch off: under IK-only the payload takes the Mini's lower cables about 3 N below
    # f_min, the watch held from 0.2 s on and froze θ_d, and this test passed without a ramp to check
    # (the hold's tension correction since session 11 moves θ_d, which showed it); the ramp is its subject
    params = loop_params("ik_lc", MINI)
    params = replace(params, safety=replace(params.safety, force_watch=False))
    held = []

    def schedule_and_watch(k, loop, sim):
        schedule(k, loop, sim)
        state = getattr(loop, "state", None)
        if state is not None and any(fault.holds for fault in state.faults):
            held.append(k)

    r = run(MINI, hold(MINI.home), 2.2, params, before_step=schedule_and_watch,
            offset_stages={"load_compensation": stage})
    assert not held
    assert np.all(np.isfinite(r.theta_d))
    assert r.offsets["load_compensation"][1490, 2] > 1e-4
    ramp = np.abs(np.diff(r.theta_d[1400:], axis=0)).max()
    offset = np.abs(inverse_kinematics(MINI, MINI.home + r.offsets["load_compensation"][1490]).q
                    - inverse_kinematics(MINI, MINI.home).q).max()
    assert ramp <= 1.5 * offset * 1e-3 / 0.2                # the 0.2 s ramp, no step


MOVE = """G21 G90 G17
G4 P4.0
G1 X1000 Y1000 Z800 F30000
G4 P0.5
M30
"""


@pytest.fixture(scope="module")
def move_program(tmp_path_factory):
    """A shortened payload_moves_ipanema3: the payload put on and identified at home, one move
    towards r = [2, 2, 1] m (to [1, 1, 0.8] m)."""
    path = tmp_path_factory.mktemp("program") / "move.gcode"
    path.write_text(MOVE)
    return str(path)


@pytest.mark.parametrize("payload", [40.0, 80.0])
def test_estimate_while_moving_within_5_percent_with_force_control(move_program, payload):
    """Section 4.1.3 (Fig. 4.7) with the default graph's controller: away from the acceleration
    singularity the estimate stays within 5 % of the payload during the move."""
    from cdpr_tools.identify import load_steps

    run = load_steps.payload_program(IPANEMA3, "force_control", payload, move_program, plant=PLANT)
    summary = load_steps.program_summary(run, payload)
    assert summary["motion_start_s"] > 3.9
    assert summary["max_estimate_error_percent"] <= 5.0


def test_pose_error_while_moving_lower_with_load_compensation(move_program):
    """IK-only with and without x_d,LC on the move with 40 kg: the compensation lowers the error."""
    from cdpr_tools.identify import load_steps

    errors = {config: load_steps.program_summary(
        load_steps.payload_program(IPANEMA3, config, 40.0, move_program, plant=PLANT),
                                                 40.0)["rms_position_error_mm"] for config in ("ik", "ik_lc")}
    assert errors["ik_lc"] < 0.5 * errors["ik"]


# --- identify first, then compensate: the mismatched plant ----------------------------------

@pytest.fixture(scope="module")
def identified_ipanema3(tmp_path_factory):
    """The user's workflow on the IPAnema 3's mismatched plant: the stiffness from tension steps
    (sensor forces) -> a robot file with the identified cable (load_robot); with it the settlement
    from a 64 kg payload run with the pose (tracker) -> load_compensation parameters."""
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify import experiments, settlement, stiffness

    tmp = tmp_path_factory.mktemp("identify")
    bag = experiments.record_stiffness_run(tmp / "stiffness", "ipanema3")
    path = stiffness.write_robot_file("ipanema3", stiffness.identify(BagReader(bag), IPANEMA3), tmp / "robot.yaml")
    robot = load_robot(path)
    bag = experiments.record_settlement_run(tmp / "settlement", IPANEMA3, hold=6.0)
    return robot, settlement.identify(BagReader(bag), robot)


def test_settlement_identified_with_the_identified_stiffness(identified_ipanema3):
    """The plant's settlement (ratio 0.3 of its own k0, T 2 s, cdpr_sim/plants/mismatch.yaml) is found
    as the ratio relative to the identified k0 (what the compensation runs on)."""
    from cdpr_sim.simulator import SimConfig, plant_of

    robot, fit = identified_ipanema3
    plant = plant_of(IPANEMA3, SimConfig())
    expected = plant.settlement_ratio * robot.cable.k0 / plant.robot.cable.k0
    assert abs(fit.ratio / expected - 1.0) < 0.05, (fit.ratio, expected)
    assert abs(fit.T / plant.settlement_time - 1.0) < 0.15, fit.T
    assert abs(robot.cable.k0 / plant.robot.cable.k0 - 1.0) < 0.04


def test_sag_cut_by_90_percent_on_the_mismatched_plant_with_the_identified_model(identified_ipanema3):
    """Section 4.1.3 on the mismatched plant, two steps of 64 kg (over 1.5 s, 6 s each: the cables
    settle with T = 2 s): IK-only + LC with the robot file's model (no settlement model) removes
    about 80 % of the sag; with the identified cable and settlement >= 90 % at 64 and 128 kg."""
    robot, fit = identified_ipanema3
    kwargs = dict(step_mass=64.0, steps=2, dwell=6.0, ramp=1.5, down=False)
    _, s_ik = _steps(IPANEMA3, "ik", POSE[:3], **kwargs)
    _, s_nom = _steps(IPANEMA3, "ik_lc", POSE[:3], **kwargs)
    params = LoadCompensationParams(tare_at_start=True, settlement_ratio=fit.ratio, settlement_time=fit.T)
    run, s_id = _steps(IPANEMA3, "ik_lc", POSE[:3], model=robot, lc_params=params, **kwargs)

    def sags(s):
        return np.array([r["z_error_mm"] - s["unloaded_z_error_mm"] for r in s["steps"]])

    cut_nom, cut_id = 1.0 - np.abs(sags(s_nom) / sags(s_ik)), 1.0 - np.abs(sags(s_id) / sags(s_ik))
    assert np.all(cut_nom < 0.9) and np.all(cut_id >= 0.9), (cut_nom, cut_id)
    assert s_id["steps"][-1]["payload_kg"] == 128.0
    assert np.all(np.isfinite(run.theta_d)) and np.all(np.isfinite(run.x_lc))

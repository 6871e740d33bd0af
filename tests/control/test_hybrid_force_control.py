"""Hybrid position and force control, thesis section 5.1: task frame (5.2), contact force, the
state machine of Fig. 5.4 with the PID (5.3), the moving average, the CFC coupling, and contact
runs against the simulator's surfaces (in-process closed loop). The plane contacts run on the
mismatched plant (the tare at the start of an approach removes the sensor offsets, which moved the
Mini's contact force by 2.2 %); the two programs on the nominal plant, each saying why."""
import itertools
from dataclasses import replace

import numpy as np
import pytest

from cdpr_control.control.loop import ControlLoopParams
from cdpr_control.control.params import control_loop_params
from cdpr_control.control.filters import LowPass
from cdpr_control.control.hybrid_force_control import (HAND_OVER_TIME, CFCCoupling, ContactHandOver,
    HPFCParams, HPFCState, HybridForceControl, MovingAverage, contact_force, expected_contact_wrench,
    APPROACH_LAG_SHARE, P_MARGIN_FACTOR, drive_ramp_lag, format_state, parse_state, select_position_feedback, task_frame)
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import run
from cdpr_sim.drive_models import DriveModel
from cdpr_sim.contacts import ContactMaterial, Plane, default_tool
from cdpr_sim.simulator import SimConfig

MINI = load_robot("ipanema3_mini")
IPANEMA3 = load_robot("ipanema3")


def shipped_hpfc(robot_name: str) -> HPFCParams:
    """The hybrid force controller's parameters of the shipped parameter file of a robot."""
    import yaml
    from importlib.resources import files

    text = files("cdpr_control.params").joinpath(f"{robot_name}.yaml").read_text()
    values = yaml.safe_load(text)["hybrid_force_controller"]["ros__parameters"]
    return HPFCParams(**{k: float(v) for k, v in values.items() if k in HPFCParams.__dataclass_fields__})


MINI_HPFC = shipped_hpfc("ipanema3_mini")
IPANEMA3_HPFC = shipped_hpfc("ipanema3")


# ---- library ------------------------------------------------------------------------------

@pytest.mark.parametrize("F", [[0, 0, -500.0], [3.0, -4.0, 12.0], [1e-3, 0, 0], [0, -6.5, -49.6]])
def test_task_frame_maps_the_desired_force_onto_its_z_axis_5_2(F):
    R = task_frame(F)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R.T @ np.asarray(F), [0, 0, np.linalg.norm(F)], atol=1e-12)   # (5.2)


def test_task_frame_keeps_the_last_direction_without_force():
    z = np.array([0.0, 0.6, -0.8])
    np.testing.assert_allclose(task_frame(np.zeros(3), z)[:, 2], z)


def test_contact_force_is_the_wrench_minus_the_weight():
    g = MINI.gravity
    m = MINI.platform.mass
    assert np.allclose(contact_force(np.r_[m * g, 0, 0, 0], m, g), 0.0)       # hanging free
    # the floor pushes up with 10 N: the platform presses 10 N down
    np.testing.assert_allclose(contact_force(np.r_[m * g + [0, 0, 10.0], 0, 0, 0], m, g), [0, 0, -10.0])
    # a known payload of 0.5 kg is no contact force
    np.testing.assert_allclose(contact_force(np.r_[(m + 0.5) * g, 0, 0, 0], m + 0.5, g), 0.0, atol=1e-12)


def test_distribution_wrench_carries_the_expected_not_the_measured_contact_force():
    hpfc = HybridForceControl(MINI, 1e-3, MINI_HPFC, enabled=True)
    g, m = MINI.gravity, MINI.platform.mass
    w = np.r_[m * g + [0, 0, 4.0], 0, 0, 0]                  # the floor pushes up with 4 N
    s = hpfc.update([0, 0, -10.0], w)                        # F_d = 10 N down: A
    dw = expected_contact_wrench(s)
    np.testing.assert_allclose((w + dw)[:3], m * g + [0, 0, 10.0], atol=1e-9)   # as if F = F_d
    np.testing.assert_allclose(dw[3:], 0.0)
    idle = HybridForceControl(MINI, 1e-3, MINI_HPFC, enabled=False).update([0, 0, -10.0], w)
    assert np.all(expected_contact_wrench(idle) == 0.0)     # I: the measured wrench unchanged


def test_the_expected_contact_force_enters_the_distribution_through_its_filter_from_zero():
    """Hybrid force control acting from the first period (enabled at start-up): the force set-point's
    wrench filter starts without the expected contact force and takes it in through its PT1, so
    the set-point the CFC holds from A on plans no contact yet (started at the full contact force,
    the resumed CFC pressed the IPAnema 3 to 108 % overshoot with its cables at 0 N)."""
    from cdpr_control.control.force_setpoint import ForceSetpoint, ForceSetpointParams

    robot, dt = IPANEMA3, 1e-3
    zero = np.zeros(6)
    w = np.r_[robot.platform.mass * robot.gravity, 0, 0, 0]       # free space, at rest
    contact = ("A", np.array([0.0, 0.0, -500.0]), np.zeros(3))
    params = ForceSetpointParams(T_wrench_filter=0.3)
    free, pressing = ForceSetpoint(robot, dt, params), ForceSetpoint(robot, dt, params)
    f_free = [free.update(robot.home, zero, zero, w).f.copy() for _ in range(3)]
    f_press = [pressing.update(robot.home, zero, zero, w, contact=contact).f.copy() for _ in range(3)]
    np.testing.assert_allclose(f_press[0], f_free[0])              # the first period: no contact in it
    alpha = 1.0 - np.exp(-dt / 0.3)                                # then the PT1's first steps
    w_d = pressing.w_d - free.w_d
    np.testing.assert_allclose(w_d[:3], [0.0, 0.0, 500.0 * (1.0 - (1.0 - alpha) ** 2)], rtol=1e-9, atol=1e-9)
    assert not np.allclose(f_press[2], f_free[2])


def test_the_approach_waits_for_the_joint_commands_switch_on_ramp():
    """The joint command ramps an offset input in over its transfer_time once it is reported active
    (OffsetInputs); x_t waits at 0 in A for T_on, so the commanded offset alpha x_t never moves
    faster than v_max. Without the wait (T_on = 0) alpha' x_t adds to the approach speed."""
    from cdpr_control.control.offset_inputs import OffsetInputs, OffsetSample

    dt, ramp = 1e-3, 0.2
    g, m = MINI.gravity, MINI.platform.mass
    w = np.r_[m * g, 0, 0, 0]                                       # free space: A all along

    def commanded_speed(T_on):
        hpfc = HybridForceControl(MINI, dt, replace(MINI_HPFC, T_on=T_on, v_max=0.05, a_max=10.0, k_env=0.0,
                                                    x_max=0.1), enabled=True)
        offsets = OffsetInputs(["hybrid_force_controller"], dt, ramp)
        z, x_t = [], []
        for k in range(600):
            s = hpfc.update([0.0, 0.0, -10.0], w)
            x_t.append(s.x_t)
            z.append(offsets.update(k * dt, {"hybrid_force_controller": OffsetSample(k * dt, s.active, s.x)})[0][2])
        return np.max(np.abs(np.diff(z))) / dt, np.array(x_t), hpfc.approach_speed(10.0)

    v_waiting, x_t, v_a = commanded_speed(ramp)     # (v_a below v_max: the lag's bound, session 13)
    assert np.all(x_t[:int(round(ramp / dt)) - 1] == 0.0) and x_t[-1] > 0.0
    assert v_waiting <= v_a * (1.0 + 1e-9)
    v_not_waiting, _, _ = commanded_speed(0.0)
    assert v_not_waiting > 1.5 * v_a


def test_the_approach_slows_where_the_impact_alone_would_press_beyond_F_d():
    """v = min(v_max, F_d / (sqrt(k_env m) + d_env)): the platform's mass hitting the stiffest expected
    surface (spring k_env and damper d_env in parallel) at v presses at most v (sqrt(k_env m) + d_env)
    before any control acts."""
    m = IPANEMA3.platform.mass
    params = replace(IPANEMA3_HPFC, k_env=2e6, d_env=0.0, T_on=0.0)
    hpfc = HybridForceControl(IPANEMA3, 1e-3, params, enabled=True)
    assert hpfc.approach_speed(150.0) == pytest.approx(150.0 / np.sqrt(2e6 * m))     # 21 mm/s
    assert hpfc.approach_speed(500.0) == params.v_max                                  # 71 mm/s > v_max
    damped = HybridForceControl(IPANEMA3, 1e-3, replace(params, d_env=2e4), enabled=True)
    assert damped.approach_speed(150.0) == pytest.approx(150.0 / (np.sqrt(2e6 * m) + 2e4))   # 5.5 mm/s
    assert damped.approach_speed(500.0) * (np.sqrt(2e6 * m) + 2e4) <= 500.0 * (1 + 1e-12)  # 18.5 mm/s
    # without k_env only the force the lag carries past the detection bounds it (session 13):
    # 0.5 (150 - 25) N / (22,000 N/m (50 + 7.0) ms) = 49.8 mm/s, and v_max for 500 N
    plain = HybridForceControl(IPANEMA3, 1e-3, replace(params, k_env=0.0))
    T_lag = params.T_F + plain.drive_lag
    assert plain.approach_speed(150.0) == pytest.approx(APPROACH_LAG_SHARE * 125.0 / (params.K_p * T_lag))
    assert plain.approach_speed(500.0) == params.v_max
    w = np.r_[m * IPANEMA3.gravity, 0, 0, 0]
    v = [damped.update([0.0, 0.0, -150.0], w).v_t for _ in range(200)]             # free space: A
    assert max(v) == pytest.approx(150.0 / (np.sqrt(2e6 * m) + 2e4))
    for name in ("k_env", "d_env"):
        with pytest.raises(ValueError, match=name):
            replace(params, **{name: -1.0}).validate()


def test_the_approach_slows_where_the_force_on_its_way_at_detection_would_carry_past_F_d():
    """Contact is detected at F_th at the earliest; what the drives' lag and the force's PT1 still
    carry then, K_p v (T_F + T_a), may use APPROACH_LAG_SHARE of F_d - F_th (session 13). On the
    Mini's drive (5.11) at 3 N, 2e6 N/m (sweep #20, seed 1: 20.6 % at 2 mm/s) the press of a
    spring stiffer than K_p stays within the band."""
    p = replace(MINI_HPFC, T_on=0.0)
    hpfc = HybridForceControl(MINI, 1e-3, p, enabled=True)
    T_lag = p.T_F + drive_ramp_lag(MINI.drive)
    v = hpfc.approach_speed(3.0)
    assert v == pytest.approx(APPROACH_LAG_SHARE * (3.0 - p.F_th) / (p.K_p * T_lag)) and v < p.v_max
    assert hpfc.approach_speed(10.0) == p.v_max                                      # larger forces: as before
    F, states = _press_on_a_spring(p, 1.3 * p.K_p, F_d=3.0, gap=0.0005, periods=4000)
    assert states[-1] == "D"
    peak = F.max()
    print(f"\n3 N on a spring of 1.3 K_p at {1e3 * v:.2f} mm/s: peak {peak:.2f} N")
    assert peak <= 1.1 * 3.0


def _press_on_a_spring(p, k, F_d=10.0, gap=0.001, periods=3000):
    """The Mini's controller pressing a spring of stiffness k [N/m] gap [m] ahead through a drive of
    the robot file ((5.11): x_t followed 16.3 ms late), read without lag by the sensors (the
    controller's own PT1 of T_F lags it), for ``periods`` -> (true force, states) per period."""
    g, m = MINI.gravity, MINI.platform.mass
    hpfc = HybridForceControl(MINI, 1e-3, p, enabled=True)
    d = MINI.drive
    drive = DriveModel.second_order(d.T_w, d.zeta, d.T_d, 1e-3, 1)
    drive.reset(np.zeros(1))
    true, states = [], []
    for _ in range(periods):
        F = k * max(0.0, float(drive.step(np.array([hpfc.x_t]))[0]) - gap)
        states.append(hpfc.update([0.0, 0.0, -F_d], np.r_[m * g + [0.0, 0.0, F], 0, 0, 0]).state)
        true.append(F)
    return np.array(true), np.array(states)


@pytest.mark.parametrize("stiffness_ratio", [1.0, 1.5, 3.0])
def test_b_stops_at_F_d_on_a_surface_stiffer_than_K_p_despite_the_force_filter(stiffness_ratio):
    """B plans its standstill on the stiffness it meets (the force's rise over x_t's, not K_p where
    the contact is stiffer) and on the force that the PT1 of T_F and the drives lag behind
    (F + (T_F + drive_ramp_lag) k v_t): through the Mini's drive the force peaks at most 0.6 % over
    F_d (10.00, 10.06, 10.00 N on springs of 1, 1.5, 3 K_p), and is at least 94.8 % of it when D
    begins. With T_F alone in the lead (before) it peaked at 10.63, 10.59 and 11.58 N; planned on K_p
    and the filtered force (before that), without a drive, B ended 5.8 %, 8.5 % and 17.9 % beyond F_d."""
    p = replace(MINI_HPFC, T_on=0.0, k_env=0.0)          # 2 mm/s, T_F 10 ms
    F, states = _press_on_a_spring(p, stiffness_ratio * p.K_p)
    assert "B" in states and states[-1] == "D"
    at_d = F[np.argmax(states == "D")]
    print(f"\nspring {stiffness_ratio} K_p: force when D begins {at_d:.2f} N, peak {F.max():.2f} N, final {F[-1]:.2f} N")
    assert 0.94 * 10.0 <= at_d and F.max() <= 1.03 * 10.0
    assert F[-1] == pytest.approx(10.0, rel=0.01)


def test_b_ends_within_its_bound_when_the_force_never_reads_F_d():
    """A sensor that reads at most 90 % of the contact force (a gain error, a plateau): B's profile
    never reaches standstill, since (F_d - F) / K_p stays ahead; B ends after B_MARGIN times its
    profile at stiffness K_p (0.46 s here) instead of creeping on to x_max (about 10 s)."""
    from cdpr_control.control.hybrid_force_control import B_MARGIN

    dt, p = 1e-3, replace(MINI_HPFC, T_on=0.0, k_env=0.0, T_F=0.0)
    g, m = MINI.gravity, MINI.platform.mass
    hpfc = HybridForceControl(MINI, dt, p, enabled=True)
    states, t_b = [], None
    for k in range(12000):
        depth = max(0.0, hpfc.x_t - 0.001)                       # a floor 1 mm ahead, 3e4 N/m
        reading = min(3e4 * depth, 0.9 * 10.0)                  # the sensor's plateau at 9 N
        s = hpfc.update([0.0, 0.0, -10.0], np.r_[m * g + [0.0, 0.0, reading], 0, 0, 0])
        if s.state == "B" and t_b is None:
            t_b, limit = k * dt, hpfc.brake_limit
        states.append(s.state)
        if s.state == "D":
            break
    assert "B" in states and states[-1] == "D"
    t_in_b = states.count("B") * dt
    assert limit == pytest.approx(B_MARGIN * ((10.0 - p.F_th) / p.K_p / p.v_max + p.v_max / p.a_max), rel=0.05)
    assert t_in_b <= limit + dt and t_in_b < 1.0 and abs(s.x_t) < p.x_max


def test_tare_at_the_approach_removes_a_sensor_offset():
    """The contact force is zeroed when an approach starts in free space: a wrench offset of 0.3 N
    (sensor offsets, weight model) is no contact force; above F_th / 2 it is taken for contact."""
    g, m = MINI.gravity, MINI.platform.mass
    offset = np.r_[m * g + [0, 0, 0.3], 0, 0, 0]             # reads 0.3 N pressing without contact
    hpfc = HybridForceControl(MINI, 1e-3, replace(MINI_HPFC, T_F=0.0), enabled=True)
    s = hpfc.update([0, 0, -10.0], offset)
    assert s.state == "A" and s.F == pytest.approx(0.0, abs=1e-12)
    s = hpfc.update([0, 0, -10.0], offset + [0, 0, 5.0, 0, 0, 0])   # 5 N of contact
    assert s.F == pytest.approx(5.0)
    untared = HybridForceControl(MINI, 1e-3, replace(MINI_HPFC, T_F=0.0, tare=False), enabled=True)
    assert untared.update([0, 0, -10.0], offset).F == pytest.approx(0.3)
    in_contact = HybridForceControl(MINI, 1e-3, replace(MINI_HPFC, T_F=0.0), enabled=True)   # F_th = 1 N
    assert in_contact.update([0, 0, -10.0], offset + [0, 0, 0.5, 0, 0, 0]).F == pytest.approx(0.8)


def test_the_tare_follows_the_reading_while_x_t_waits_but_not_a_contact():
    """While x_t waits at 0 in A (T_on) the platform stands and only the cable force control's
    pre-tension changes the cable forces: what the reading drifts by then (the sensors' slope errors
    of those changes) is tared, in both directions below F_th / 2; a rise of F_th / 2 or more is
    contact and is not. A negative reading at the start is tared whatever its size. Once x_t
    moves, the tare stays."""
    g, m = MINI.gravity, MINI.platform.mass
    params = replace(MINI_HPFC, T_F=0.0, T_on=0.1)                # F_th 1 N
    weight = np.r_[m * g, 0, 0, 0]
    hpfc = HybridForceControl(MINI, 1e-3, params, enabled=True)
    s = hpfc.update([0, 0, -10.0], weight + [0, 0, -3.0, 0, 0, 0])    # reads -3 N: an offset, tared
    assert s.state == "A" and s.F == pytest.approx(0.0, abs=1e-12)
    for drift in np.linspace(-3.0, -3.8, 20):                         # the pre-tension: -0.8 N more
        s = hpfc.update([0, 0, -10.0], weight + [0, 0, drift, 0, 0, 0])
        assert s.F == pytest.approx(0.0, abs=1e-12) and s.x_t == 0.0
    s = hpfc.update([0, 0, -10.0], weight + [0, 0, -3.8 + 0.4, 0, 0, 0])   # below F_th / 2: followed
    assert s.F == pytest.approx(0.0, abs=1e-12)
    s = hpfc.update([0, 0, -10.0], weight + [0, 0, -3.4 + 2.0, 0, 0, 0])   # 2 N: contact, B
    assert s.F == pytest.approx(2.0) and s.state == "B"
    moving = HybridForceControl(MINI, 1e-3, params, enabled=True)
    for _ in range(150):                                             # past T_on: x_t moves
        s = moving.update([0, 0, -10.0], weight)
    assert s.x_t > 0.0
    s = moving.update([0, 0, -10.0], weight + [0, 0, -0.3, 0, 0, 0])    # no tare once x_t moves
    assert s.F == pytest.approx(-0.3)


def test_cfc_runs_in_contact_with_the_average_feed_forward_and_the_live_contact_share():
    """Section 5.1.2: paused in A-C (without pre-contact forces); in D the error and the feed-forward
    follow the set-point through the moving average, but along a (the contact force's direction in
    cable forces) the error is live and the feed-forward goes to the live one within HAND_OVER_TIME;
    back in I it blends back. (Session 10's error on the live set-point across a against the
    averaged feed-forward held the PI at its saturation for the average's 2 s: docs.)"""
    c = CFCCoupling(0.01, 1e-3)                              # 10 samples
    a = np.r_[-np.ones(4), np.ones(4)] / np.sqrt(8.0)
    f0 = np.full(8, 100.0)
    f1 = f0 + np.r_[np.full(4, 50.0), np.full(4, 250.0)]      # more tension and a contact share
    for state in ("A", "B", "C"):
        f_err, f_ff, paused = c.contact_update(state, f0 if state == "A" else f1, a)
        assert paused and np.allclose(f_err, f0) and np.allclose(f_ff, f0)
    f_err, f_ff, paused = c.contact_update("D", f1, a)
    share = 1e-3 / HAND_OVER_TIME                             # the hand-over ramps in
    assert not paused
    P = np.eye(8) - np.outer(a, a)
    assert a @ f_err == pytest.approx(a @ f1)                 # the error: live along a,
    np.testing.assert_allclose(P @ f_err, P @ (0.9 * f0 + 0.1 * f1))      # averaged across it
    assert a @ f_ff == pytest.approx(a @ (f0 + share * (f1 - f0)))       # feed-forward: ramped along a,
    np.testing.assert_allclose(P @ f_ff, P @ (0.9 * f0 + 0.1 * f1))      # averaged across it
    for _ in range(int(HAND_OVER_TIME / 1e-3)):
        f_err, f_ff, paused = c.contact_update("D", f1, a)
    np.testing.assert_allclose(f_ff, f1)
    np.testing.assert_allclose(f_err, f1)
    outs = [c.contact_update("I", f0, a) for _ in range(12)]
    assert not outs[0][2] and np.allclose(outs[-1][1], f0)


def test_the_hand_over_offset_ramps_in_with_the_cfc_feed_forward_along_the_task_axis():
    """x_comp = -F_ff / k_t z_t (ContactHandOver, in HybridForceStage): F_ff the expected contact
    force F_d through the PT1 of the force distribution's wrench filter, 0 while the CFC is paused
    (A-C), ramped in over HAND_OVER_TIME in D (as CFCCoupling.contact_update ramps the feed-forward
    along a), all of it in R and I; 0 while the CFC's output is not applied."""
    dt, k_t, T_c = 1e-3, 12600.0, 0.3
    z = np.array([0.0, 0.0, -1.0])
    hand_over, off = ContactHandOver(T_c, dt), ContactHandOver(T_c, dt)
    F_c = LowPass(T_c, dt)
    n_ramp = int(round(HAND_OVER_TIME / dt))
    states = ["I"] * 5 + ["A"] * 50 + ["B"] * 30 + ["D"] * 400 + ["R"] * 100 + ["I"] * 100
    F_d = [500.0] * 485 + list(np.linspace(500.0, 0.0, 100)) + [0.0] * 100
    k_d = states.index("D")
    for k, (state, F) in enumerate(zip(states, F_d)):
        hpfc = HPFCState(state, True, z, 500.0 * z, np.zeros(3), F, 0.0, F, 0.0, 0.0, 0.0, False, np.zeros(6))
        F_exp = float(F_c.update(F if state != "I" else 0.0))
        x_comp = hand_over.update(hpfc, k_t, True)
        assert np.all(x_comp[3:] == 0.0) and np.all(x_comp[:2] == 0.0)
        assert np.all(off.update(hpfc, k_t, False) == 0.0)
        F_ff = -x_comp[2] / z[2] * k_t
        if state in "ABC" or k < 5:
            assert F_ff == 0.0, (k, state)
        elif state == "D" and k - k_d < n_ramp:
            assert F_ff == pytest.approx((k - k_d + 1) * dt / HAND_OVER_TIME * F_exp, rel=1e-9), (k, state)
        else:
            assert F_ff == pytest.approx(F_exp, rel=1e-12) and F_ff > 0.0, (k, state)


def test_absorb_moves_x_t_and_its_integral_part_in_contact_only():
    hpfc = HybridForceControl(MINI, 1e-3, MINI_HPFC, enabled=True)
    hpfc.absorb(1e-3)
    assert hpfc.x_t == 0.0                                   # idle: nothing to take over
    hpfc.state, hpfc.x_t, hpfc.integrator = "D", 2e-3, 1e-3
    hpfc.absorb(5e-4)
    assert hpfc.x_t == pytest.approx(2.5e-3) and hpfc.integrator == pytest.approx(1.5e-3)


def test_selection_removes_the_pose_error_along_the_force_axis_only():
    x_d = np.array([0.1, 0.2, 0.3, 0.01, 0.02, 0.03])
    x = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    z = np.array([0.0, 0.6, 0.8])
    e = x_d - select_position_feedback(x_d, x, z)
    assert e[:3] @ z == pytest.approx(0.0, abs=1e-15)
    np.testing.assert_allclose(e[:3], (np.eye(3) - np.outer(z, z)) @ x_d[:3])
    np.testing.assert_allclose(e[3:], x_d[3:])


def test_moving_average_is_the_mean_of_the_window():
    ma = MovingAverage(0.01, 1e-3)            # 10 samples
    ma.reset(np.zeros(2))
    u = np.random.default_rng(0).normal(size=(50, 2))
    out = np.array([ma.update(v).copy() for v in u])
    np.testing.assert_allclose(out[-1], u[-10:].mean(axis=0))
    np.testing.assert_allclose(out[4], u[:5].sum(axis=0) / 10)   # window pre-filled with 0


class Wall:
    """1-D plant for the library tests: a wall at ``gap`` along the task axis with stiffness k; the
    platform follows x_t through a first-order lag (the robot); the wrench is what the cables feel."""

    def __init__(self, robot, k, gap, T=0.01, dt=1e-3):
        self.robot, self.k, self.gap, self.T, self.dt = robot, k, gap, T, dt
        self.x = 0.0

    def wrench(self, x_t):
        self.x += self.dt / self.T * (x_t - self.x)
        F = max(0.0, self.k * (self.x - self.gap))               # pressing down along -z
        return np.r_[self.robot.platform.mass * self.robot.gravity + [0, 0, F], 0, 0, 0], F


def _drive(hpfc, wall, F_d, n, log):
    for _ in range(n):
        s = hpfc.update([0, 0, -F_d], wall.wrench(hpfc.x_t)[0])
        log.append(s)
    return log


def _sequence(states):
    return [s for s, _ in itertools.groupby(x.state for x in states)]


def test_state_machine_approach_brake_contact_then_loss_and_release_fig_5_4():
    p = HPFCParams(K_p=20000.0, T_i=0.3, T_d=0.0, F_th=1.0, v_max=0.01, a_max=1.0, x_max=0.02, T_F=0.0)
    hpfc = HybridForceControl(MINI, 1e-3, p, enabled=True)
    wall = Wall(MINI, 20000.0, 0.003)
    log = _drive(hpfc, wall, 10.0, 2000, [])
    assert _sequence(log) == ["A", "B", "D"]
    approach = [s.v_t for s in log if s.state == "A"]
    assert max(approach) == pytest.approx(p.v_max)                # A at v_max,HPFC
    assert wall.k * (wall.x - wall.gap) == pytest.approx(10.0, rel=0.01)
    wall.gap += 0.002                                             # the surface moves away
    log = _drive(hpfc, wall, 10.0, 2000, log)
    assert _sequence(log) == ["A", "B", "D", "C", "B", "D"]
    assert wall.k * (wall.x - wall.gap) == pytest.approx(10.0, rel=0.01)
    x_before = log[-1].x_t
    log = _drive(hpfc, wall, 0.0, 1000, log)                      # F_d back to 0: release
    assert _sequence(log)[-2:] == ["R", "I"] and log[-1].x_t == 0.0
    steps = np.abs(np.diff([s.x_t for s in log]))
    assert steps[-1000:].max() <= p.v_max * 1e-3 + 1e-12          # x_t back to 0 at most at v_max
    assert x_before > 0.004


def test_pid_5_3_gain_is_the_force_error_over_the_stiffness():
    p = HPFCParams(K_p=20000.0, T_i=2.0, T_d=0.0, T_F=0.0)
    hpfc = HybridForceControl(MINI, 1e-3, p, enabled=True)
    hpfc.state, hpfc.integrator, hpfc.x_t = "D", 0.0, 0.0
    w = np.r_[MINI.platform.mass * MINI.gravity + [0, 0, 30.0], 0, 0, 0]     # F = 30 N
    s = hpfc.update([0, 0, -50.0], w)                                        # e_F = 20 N
    assert s.e_F == pytest.approx(20.0)
    # x_t = e_F / K_p (1 + dt / T_i) after one period (5.3), forward Euler
    assert s.x_t == pytest.approx(20.0 / 20000.0 + 1e-3 * 20.0 / (20000.0 * 2.0))
    np.testing.assert_allclose(s.x[:3], [0, 0, -s.x_t])                     # along the task z axis


def test_no_contact_saturates_the_approach_at_x_max():
    p = HPFCParams(F_th=1.0, v_max=0.01, a_max=1.0, x_max=0.005)
    hpfc = HybridForceControl(MINI, 1e-3, p, enabled=True)
    log = _drive(hpfc, Wall(MINI, 1e4, 1.0), 10.0, 2500, [])          # (3.1 mm/s: the lag's bound)
    assert log[-1].state == "A" and log[-1].saturated and log[-1].x_t == pytest.approx(0.005)


def test_non_finite_inputs_never_give_nan():
    hpfc = HybridForceControl(MINI, 1e-3, MINI_HPFC, enabled=True)
    for F_d0, w in (([np.nan, 0, 0], np.zeros(6)), ([0, 0, -5.0], np.full(6, np.nan)), ([0, 0, np.inf], np.zeros(6))):
        s = hpfc.update(F_d0, w)
        assert np.all(np.isfinite(s.x)) and np.isfinite(s.x_t)


def test_disabled_gives_zero_offset_and_idle():
    hpfc = HybridForceControl(MINI, 1e-3, MINI_HPFC, enabled=False)
    s = hpfc.update([0, 0, -10.0], np.r_[MINI.platform.mass * MINI.gravity, 0, 0, 0])
    assert s.state == "I" and not s.active and np.all(s.x == 0.0)


def test_cfc_coupling_pauses_in_contact_and_blends_back_without_a_step():
    c = CFCCoupling(0.01, 1e-3)
    f0, f1 = np.full(8, 7.0), np.full(8, 9.0)
    out, paused = c.update("I", f0)
    assert not paused and np.allclose(out, f0)
    for state, f in (("A", f0), ("B", f1), ("D", f1), ("C", f1), ("D", f1), ("R", f1)):
        out, paused = c.update(state, f)
        assert paused and np.allclose(out, f0)                   # held at the pause's set-point
    outs = [c.update("I", f1)[0] for _ in range(20)]
    assert not c.update("I", f1)[1]
    assert np.max(np.abs(np.diff(np.array([f0] + outs), axis=0))) < 0.25 * (f1 - f0).max()
    np.testing.assert_allclose(outs[-1], f1)


def test_state_field_of_the_controller_state_round_trips():
    assert parse_state(format_state("hybrid_force_controller", "D")) == "D"
    assert parse_state("ospc") is None


# ---- closed loop against the simulated surface ----------------------------------------------

def _floor_run(robot, hpfc, F_d, gap, duration, before_step=None, stiffness=1e6, force=None):
    radius, centre = default_tool(np.asarray(robot.b))
    floor = Plane.floor(robot.home[2] + centre[2] - radius - gap,
                        ContactMaterial(stiffness=stiffness, damping=0.01 * stiffness))
    force = force or (lambda t: np.array([0.0, 0.0, -F_d]))
    source = lambda t: (robot.home, np.zeros(6), np.zeros(6), force(t))   # noqa: E731
    return run(robot, source, duration, control_loop_params(robot, hpfc=hpfc, hpfc_enabled=True),
               config=SimConfig(obstacles=(floor,)), before_step=before_step)


def contact_figures(r, F_d, dt=1e-3):
    """Overshoot [%] and settling time [s] as section 5.1.3 defines them, on the true contact force:
    overshoot = (max F - F_d) / F_d; settling = from the first contact until |F_d - F| stays < 2 % F_d."""
    F = r.w_contact[:, 2]
    first = int(np.argmax(F > 0.0))
    outside = np.nonzero(np.abs(F - F_d) > 0.02 * F_d)[0]
    return 100.0 * (F.max() - F_d) / F_d, (outside[-1] + 1 - first) * dt, F


def _print_figures(name, F_d, overshoot, settling, F):
    print(f"\n{name} F_d = {F_d} N: overshoot {overshoot:.1f} % (table 5.2: 9.98 % mean, 11.3 % max), "
          f"settling {settling:.2f} s (table 5.2: 2.25 s mean), final {F[-1]:.2f} N")


def floor_program_run(duration=None):
    """The shipped floor_contact_ipanema3.gcode against a stiff floor 10 mm below the tool tip."""
    from cdpr_control import programs
    from cdpr_control.motion.gcode import parse_gcode
    from cdpr_control.motion.interpolation import Interpolator
    from cdpr_sim.closed_loop import program

    robot = IPANEMA3
    interp = Interpolator(parse_gcode(programs.read("floor_contact_ipanema3"), start_pose=robot.home), dt=1e-3)
    radius, centre = default_tool(np.asarray(robot.b))
    floor = Plane.floor(robot.home[2] + centre[2] - radius - 0.01, ContactMaterial(stiffness=1e6, damping=1e4))
    # nominal plant: the mismatched one's cables settle under the contact's loads (cdpr_sim.plant.Settlement,
    # section 4.1.3), which leaves the platform 4.9 mm above the programmed pose after the release
    # while the pose estimate (which cannot see the settlement) is back within 1.2 mm; the release
    # criterion is about the controller. The 500 N contact on the mismatched plant: test below.
    return run(robot, program(interp), duration or interp.duration, control_loop_params(robot, hpfc=IPANEMA3_HPFC),
               config=SimConfig(plant="nominal", obstacles=(floor,)))


def test_floor_contact_program_ipanema3_500N_a_b_d_within_2_percent_and_release():
    """Section 5.1.3: 500 N on the floor approached at 50 mm/s; steady within 2 % of F_d (the
    true contact force of the simulator), then released to the programmed pose."""
    r = floor_program_run()
    assert _sequence(r.hpfc) == ["I", "A", "B", "D", "R", "I"]
    states = np.array([s.state for s in r.hpfc])
    hold = np.nonzero((states == "D") & np.isclose([s.F_d for s in r.hpfc], 500.0))[0]
    contact = slice(int(np.argmax(states == "A")), hold[-1] + 1)
    overshoot, settling, F = contact_figures(_slice_run(r, contact), 500.0)
    _print_figures("IPAnema 3 floor program", 500.0, overshoot, settling, F)
    assert np.all(np.abs(F[-1000:] - 500.0) <= 0.02 * 500.0)       # the last second of the hold
    assert settling < 3.0
    # the CFC runs in D (section 5.1.2) and keeps every cable tensed: the distribution's wrench
    # carries the expected contact force. From 0.3 s after B (where the CFC is paused, as in the
    # thesis, and the cables the floor unloads go slack) to the end of the run, release included
    k_d = int(np.argmax(states == "D"))
    f_min = IPANEMA3.cable.f_min
    print(f"cables from 0.3 s into D to the end: min {r.f[k_d + 300:].min():.0f} N (f_min {f_min.min():.0f} N); "
          f"in B: min {r.f[states == 'B'].min():.0f} N")
    assert np.all(r.f[k_d + 300:] >= f_min)
    # the CFC resuming in D and the contact force passing to its feed-forward do not step the drive
    # command (a step of the hand-over gave 1.5 mm in one period; approaching at 50 mm/s: 0.025 mm)
    step = np.abs(np.diff(r.theta_d, axis=0)).max()
    print(f"largest drive command step: {1e3 * step:.3f} mm per period")
    assert step < 2e-4
    assert r.w_contact[-1, 2] == 0.0
    # released without a jump: the platform never moves faster than about v_max,HPFC
    k_r = int(np.argmax(states == "R"))
    v = np.linalg.norm(np.diff(r.x[k_r:, :3], axis=0), axis=1) / 1e-3
    offset = 1e3 * np.linalg.norm(r.x[-1, :3] - IPANEMA3.home[:3])
    print(f"release: platform speed max {1e3 * v.max():.1f} mm/s; {offset:.1f} mm from the programmed pose "
          f"{r.t[-1] - r.t[k_r]:.1f} s after the release began")
    assert v.max() < 2.0 * IPANEMA3_HPFC.v_max
    # the distribution's wrench carries the expected, not the measured, contact force: no filtered
    # remains of the 500 N press the resuming CFC (was 4.1 mm below the programmed pose)
    assert offset <= 0.5


def _slice_run(r, k):
    class Part:
        w_contact = r.w_contact[k]
    return Part


def test_contact_on_a_plane_mini_10N_a_b_d_within_2_percent():
    r = _floor_run(MINI, MINI_HPFC, 10.0, 0.001, 2.5)
    assert _sequence(r.hpfc) == ["A", "B", "D"]
    overshoot, settling, F = contact_figures(r, 10.0)
    _print_figures("IPAnema 3 Mini plane", 10.0, overshoot, settling, F)
    assert np.all(np.abs(F[-200:] - 10.0) <= 0.02 * 10.0)
    assert settling < 2.0


def test_contact_on_a_plane_ipanema3_500N_mismatched_plant_cables_tensed():
    """Section 5.1.3's 500 N on the mismatched plant (sensor gain and offset errors, other cables):
    A -> B -> D, within 2 % of F_d, and the cable force controller, running in D, keeps every cable
    at or above f_min while the floor carries the platform (the expected contact force is in the
    distribution's wrench)."""
    r = _floor_run(IPANEMA3, IPANEMA3_HPFC, 500.0, 0.001, 4.5)
    assert _sequence(r.hpfc) == ["A", "B", "D"]
    overshoot, settling, F = contact_figures(r, 500.0)
    _print_figures("IPAnema 3 plane, mismatched plant", 500.0, overshoot, settling, F)
    states = np.array([s.state for s in r.hpfc])
    k_d = int(np.argmax(states == "D"))
    print(f"cables from 0.3 s into D: min {r.f[k_d + 300:].min():.0f} N; in B: min {r.f[states == 'B'].min():.0f} N")
    assert np.all(np.abs(F[-500:] - 500.0) <= 0.02 * 500.0)
    assert settling < 3.0
    assert np.all(r.f[k_d + 300:] >= IPANEMA3.cable.f_min)


def test_contact_lost_reapproach_and_release_to_the_programmed_pose():
    robot, p = MINI, MINI_HPFC
    radius, centre = default_tool(np.asarray(robot.b))
    moved = {}

    def move_floor(k, loop, sim):
        if k == 1500:                                         # the surface drops 1 mm
            sim.place_obstacle(0, (0.0, 0.0, robot.home[2] + centre[2] - radius - 0.002))
            moved["k"] = k
    # F_d = 10 N until 3 s, then back to 0 N in 0.2 s: the release
    force = lambda t: np.array([0.0, 0.0, min(0.0, -10.0 + 50.0 * max(0.0, t - 3.0))])  # noqa: E731
    r = _floor_run(robot, p, 10.0, 0.001, 5.0, before_step=move_floor, force=force)
    seq = _sequence(r.hpfc)
    assert seq == ["A", "B", "D", "C", "B", "D", "R", "I"]
    F = r.w_contact[:, 2]
    assert F[moved["k"] + 20] == 0.0                            # contact lost physically
    assert abs(F[2990] - 10.0) <= 0.2                           # back at F_d before the release
    released = np.array([s.state for s in r.hpfc]) == "I"
    assert released[-1] and F[-1] == 0.0
    # back at the programmed pose, without a jump: the platform moves at most at about v_max,HPFC
    assert np.linalg.norm(r.x[-1, :3] - robot.home[:3]) < 1e-4
    k_r = next(i for i, s in enumerate(r.hpfc) if s.state == "R")
    v = np.linalg.norm(np.diff(r.x[k_r:, :3], axis=0), axis=1) / 1e-3
    print(f"\nrelease: platform speed max {1e3 * v.max():.1f} mm/s (v_max,HPFC {1e3 * p.v_max:.0f} mm/s)")
    assert v.max() < 2.0 * p.v_max


def cylinder_program_run(stiffness=1e6, friction=0.3):
    """The shipped cylinder_contact_force.gcode on the IPAnema 3 with its M103/M104 against a barrel
    of radius 180 mm around a 20 mm tool sphere at the platform origin (so that the origin moves on
    the programmed 200 mm circle) -> (run, states, F_n along the surface normal, F_d, moving in D)."""
    from cdpr_control import programs
    from cdpr_control.control.force_setpoint import ForceSetpointParams
    from cdpr_control.motion.gcode import parse_gcode
    from cdpr_control.motion.interpolation import Interpolator
    from cdpr_sim.closed_loop import program
    from cdpr_sim.contacts import Cylinder, PlatformShape

    robot, tool = IPANEMA3, 0.02
    interp = Interpolator(parse_gcode(programs.read("cylinder_contact_force"), start_pose=robot.home), dt=1e-3)
    barrel = Cylinder((0.0, 0.0, -0.28), (1.0, 0.0, 0.0), 0.2 - tool, 0.9,
                      ContactMaterial(stiffness, 0.01 * stiffness, friction))
    config = SimConfig(plant="nominal", obstacles=(barrel,), platform_shape=PlatformShape("sphere", tool, (0.0, 0.0, 0.0)))
    # f_min of the distribution as params/ipanema3.yaml plans it
    params = ControlLoopParams(force=ForceSetpointParams(f_min=np.full(robot.m, 150.0)), hpfc=IPANEMA3_HPFC)
    r = run(robot, program(interp), interp.duration + 0.5, params, config=config)
    states = np.array([s.state for s in r.hpfc])
    rel = r.x[:, 1:3] - [0.0, -0.28]
    normal = np.c_[np.zeros(len(rel)), rel / np.linalg.norm(rel, axis=1)[:, None]]
    F_n = np.sum(r.w_contact[:, :3] * normal, axis=1)             # the barrel pushes along the normal
    F_d = np.array([s.F_d for s in r.hpfc])
    speed = np.r_[0.0, np.linalg.norm(np.diff(r.x_d[:, :3], axis=0), axis=1) / 1e-3]
    moving = (speed > 0.005) & (states == "D") & (F_d > 49.0)
    return r, states, F_n, F_d, moving


def test_cylinder_program_presses_follows_and_releases():
    """Section 5.1.3, Fig. 5.7: press 50 N on the barrel (1e6 N/m, friction 0.3), follow it, release."""
    r, states, F_n, F_d, moving = cylinder_program_run()
    assert _sequence(r.hpfc) == ["I", "A", "B", "D", "R", "I"]     # never lost the barrel
    error = np.abs(F_n[moving] - F_d[moving])
    c = IPANEMA3.cable
    print(f"\ncylinder: {moving.sum() * 1e-3:.1f} s moving in contact, |F - F_d| max {error.max():.1f} N, "
          f"rms {np.sqrt(np.mean(error ** 2)):.1f} N, after the first 5 s max "
          f"{error[5000:].max():.1f} N; cable forces {r.f.min():.0f}..{r.f.max():.0f} N")
    assert moving.sum() > 40_000                                   # 40 s of following
    # with the CFC running in D (max 9.3 N, rms 0.7 N; held in D it was 22 N and 5.5 N)
    assert error.max() < 15.0 and np.sqrt(np.mean(error ** 2)) < 2.0
    assert np.all(r.f >= c.f_min) and np.all(r.f <= c.f_max)
    np.testing.assert_allclose(r.x[-1, :3], r.x_d[-1, :3], atol=1e-3)   # released and back home


def _sweep_contact(pose_index, seed, fraction, stiffness):
    """A contact case of `cdpr validate` (cdpr_tools.validate.cases.contact_case, the shipped parameter
    file, the default mismatched plant) at an IPAnema 3 pose of the sweep's grid."""
    from cdpr_tools.validate.cases import CaseSpec, contact_case
    from cdpr_tools.validate.grid import sweep_poses

    pose = sweep_poses(IPANEMA3)[pose_index]
    return contact_case(CaseSpec("contact", "ipanema3", pose_index, list(pose.x), pose.border, "mismatched", seed,
                                 {"fraction": fraction, "stiffness": stiffness}))


def test_sweep_worst_case_500N_on_2e6_within_the_bands():
    """The sweep's worst contact case before (issue 25): IPAnema 3 pose #8 [2.160, 3.479, 1.535] c -5 deg,
    mismatched seed 1, 500 N on 2e6 N/m. At 50 mm/s the impact alone pressed 866 N (73 %
    overshoot); approached at 500 N / (sqrt(k_env m) + d_env) = 18.5 mm/s with B planned on the
    stiffness met, every band of the sweep holds (2.5 %, 0.97 s, 0 s slack when measured)."""
    r = _sweep_contact(8, 1, 1.0, 2e6)
    print(f"\n{r.status}: " + ", ".join(f"{k} {v:.3g}" for k, v in r.metrics.items()))
    assert r.status == "passed", (r.note, r.checks)
    assert r.metrics["overshoot_percent"] <= 20.0


@pytest.mark.parametrize("stiffness_ratio", [0.5, 3.0])
def test_pid_p_part_divides_by_the_stiffness_met_where_it_is_stiffer_than_K_p(stiffness_ratio):
    """In D the P part of (5.3) is e_F over the stiffness met in B where that is above K_p (the loop's
    gain at high frequency stays the thesis's; at 2.1 K_p the IPAnema 3's contact at sweep pose #33
    grew a 52 Hz oscillation), over K_p where the contact is softer; the I part keeps 1 / (K_p T_i)."""
    p = HPFCParams(K_p=20000.0, T_i=0.3, T_d=0.0, F_th=1.0, v_max=0.01, a_max=1.0, x_max=0.02, T_F=0.0)
    hpfc = HybridForceControl(MINI, 1e-3, p, enabled=True)
    wall = Wall(MINI, stiffness_ratio * p.K_p, 0.003)
    log = _drive(hpfc, wall, 10.0, 3000, [])
    assert _sequence(log) == ["A", "B", "D"]
    # measured in B (through the wall's lag: 10,764 and 75,063 N/m here), on the wall's side of K_p
    assert (hpfc.k_contact > 2.0 * p.K_p) if stiffness_ratio > 1.0 else (hpfc.k_contact < p.K_p)
    k = max(p.K_p, P_MARGIN_FACTOR * hpfc.k_contact)
    assert (k > p.K_p) == (stiffness_ratio > 1.0)
    integrator, x_t = hpfc.integrator, hpfc.x_t
    w = np.r_[MINI.platform.mass * MINI.gravity + [0, 0, 6.0], 0, 0, 0]      # F = 6 N: e_F = 4 N
    s = hpfc.update([0, 0, -10.0], w)
    assert s.x_t == pytest.approx(4.0 / k + integrator + 1e-3 * 4.0 / (p.K_p * p.T_i), rel=1e-9)
    assert s.x_t != pytest.approx(x_t)

"""The hand's reserve of the force set-point while a user guides (section 5.2, docs/admittance.md):
every cable is planned within [f_min + r, f_max - r], r RESERVE_RING times the largest cable force
the user's wrench takes (the swing of a release, not only its static change), so that the cables
keep their limits when the hand lets go; without a user the distribution is the thesis'."""
import numpy as np
import pytest

from cdpr_control.control.force_setpoint import (RESERVE_RELEASE_TIME, RESERVE_RING, RESERVE_SHARE, ForceSetpoint,
    MarginLP, largest_margin, user_forces)
from cdpr_control.force_distribution import Status
from cdpr_control.control.params import control_loop_params
from cdpr_control.model.dynamics import platform_wrench
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot
from cdpr_sim.hand import Segment
from cdpr_sim.hand_guiding import guiding_run
from cdpr_sim.simulator import SimConfig

DT = 1e-3
MINI = load_robot("ipanema3_mini")
HAND = np.r_[12.5, 0.0, 0.0, 0.0, 0.0, 0.0]     # N: a 13 N push along x less the 0.5 N dead band


def _at_rest(fs, robot, periods, w_user=None):
    """``periods`` periods holding home, the measured wrench the model's, the user's wrench given."""
    x, zero = np.asarray(robot.home, dtype=float), np.zeros(6)
    w = platform_wrench(robot, x, zero, zero)
    fs.set_user_wrench(w_user)
    return [fs.update(x, zero, zero, w) for _ in range(periods)]


def _expected_reserve(robot, w_user):
    AT = inverse_kinematics(robot, np.asarray(robot.home, dtype=float)).AT
    return RESERVE_RING * float(np.abs(np.linalg.lstsq(AT, w_user, rcond=None)[0]).max())


def test_without_a_user_the_distribution_is_the_minimal_tension():
    fs = ForceSetpoint(MINI, DT, control_loop_params(MINI).force)
    res = _at_rest(fs, MINI, 50)[-1]
    assert fs.reserve == 0.0
    assert res.f.min() == pytest.approx(7.5, abs=1e-6)          # the file's planned f_min


def test_the_user_wrench_raises_every_cable_by_its_reserve_at_the_tension_rate():
    params = control_loop_params(MINI).force
    fs = ForceSetpoint(MINI, DT, params)
    _at_rest(fs, MINI, 50)
    r = _expected_reserve(MINI, HAND)
    assert r > 2.0 * RESERVE_RING                                # N: what a 13 N push puts on a cable, twice
    rate = params.tension_rate * float(np.max(fs.distributor.f_max - fs.distributor.f_min))
    first = _at_rest(fs, MINI, 1, HAND)[-1]
    assert fs.reserve == pytest.approx(rate * DT)                # rises smoothly, not as a step
    assert first.f.min() == pytest.approx(7.5 + rate * DT, abs=1e-6)
    res = _at_rest(fs, MINI, int(np.ceil(r / (rate * DT))) + 5, HAND)[-1]
    assert fs.reserve == pytest.approx(r)
    assert res.f.min() == pytest.approx(7.5 + r, abs=1e-6)
    assert res.f.max() <= 40.0 - r + 1e-6                        # and from f_max: a release loads others
    np.testing.assert_array_equal(res.f_min, fs.distributor.f_min)   # reported with the planned limits
    AT = inverse_kinematics(MINI, np.asarray(MINI.home, dtype=float)).AT
    np.testing.assert_allclose(AT @ res.f, -fs.w_d, atol=1e-6)   # still balances the wrench set-point


def test_the_reserve_stays_while_the_cables_ring_out_and_then_goes():
    fs = ForceSetpoint(MINI, DT, control_loop_params(MINI).force)
    _at_rest(fs, MINI, 2000, HAND)
    r = fs.reserve
    _at_rest(fs, MINI, int(round(0.1 / DT)))                     # the hand let go 0.1 s ago
    assert fs.reserve == pytest.approx(r * (1.0 - DT / RESERVE_RELEASE_TIME) ** 100)
    assert fs.reserve > 0.8 * r
    res = _at_rest(fs, MINI, int(round(8.0 / DT)))[-1]
    assert fs.reserve == 0.0
    assert res.f.min() == pytest.approx(7.5, abs=1e-6)


def test_largest_margin_is_the_margin_the_pose_leaves_from_both_limits():
    x, zero = np.asarray(MINI.home, dtype=float), np.zeros(6)
    AT, w = inverse_kinematics(MINI, x).AT, platform_wrench(MINI, x, zero, zero)
    f_min, f_max = np.full(8, 7.5), np.full(8, 40.0)
    t = largest_margin(AT, w, f_min, f_max)
    assert 0.0 < t < 16.25
    qp = ForceSetpoint(MINI, DT, control_loop_params(MINI).force).distributor.qp
    assert qp.solve(AT, w, f_min=f_min + 0.999 * t, f_max=f_max - 0.999 * t).status == Status.FEASIBLE
    assert qp.solve(AT, w, f_min=f_min + 1.01 * t, f_max=f_max - 1.01 * t).status == Status.INFEASIBLE
    assert largest_margin(AT, w + np.r_[0.0, 0.0, -400.0, 0.0, 0.0, 0.0], f_min, f_max) == -np.inf


def test_a_reserve_beyond_the_pose_s_margin_is_limited_to_it():
    """Near the border, or for a strong hand, r is limited to RESERVE_SHARE of the largest margin:
    the set-point stays feasible and continuous instead of falling back to the plain one."""
    fs = ForceSetpoint(MINI, DT, control_loop_params(MINI).force)
    fs.params.tension_rate = 0.0                                 # (at once)
    res = _at_rest(fs, MINI, 5, np.r_[400.0, 0.0, 0.0, 0.0, 0.0, 0.0])[-1]
    AT = inverse_kinematics(MINI, np.asarray(MINI.home, dtype=float)).AT
    t = largest_margin(AT, fs.w_d, fs.distributor.f_min, fs.distributor.f_max)
    assert fs.reserve > t
    assert res.f.min() == pytest.approx(7.5 + RESERVE_SHARE * t, abs=1e-6)
    assert res.f.max() <= 40.0 - RESERVE_SHARE * t + 1e-6


def test_the_mini_keeps_f_min_when_a_13_N_push_is_let_go_at_once():
    """The validation sweep's harshest push (rising over 0.1 s, held 1 s, let go at once) at the
    Mini pose where, without the reserve, a cable rang down to 2.5 N 18 ms after the release
    (f_min 5 N; default mismatched plant, seed 3)."""
    enable, push, release = 0.5, 1.0, 2.0
    wrench = (13.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    g = guiding_run([Segment(push, wrench, "ramp", 0.1), Segment(push + 0.1, wrench, "step"),
                     Segment(release, release=True)], release + 0.4, robot_name="ipanema3_mini",
                    x_hold=[0.206, 0.107, -0.172, 0.0, 0.0, 0.0], config=SimConfig(plant_seed=3), enable_at=enable)
    r = g.run
    moved = r.x_d[r.t > release][-1, 0] - r.x_d[0, 0]
    assert moved > 1e-3                                          # it was guided along the push
    assert r.f[r.t > enable].min() >= MINI.cable.f_min.min()


def _guided_path(robot, periods, amplitude, push):
    """A guided path about home: (A^T, w) per period, the pose swinging by ``amplitude`` [m] and the
    wrench by ``push`` [N] (a hand moving the platform around)."""
    zero = np.zeros(6)
    for k in range(periods):
        x = np.asarray(robot.home, dtype=float).copy()
        x[:3] += amplitude * np.sin(np.r_[1.0, 1.3, 0.7] * k * 0.003)
        w = platform_wrench(robot, x, zero, zero) + push * np.r_[np.sin(np.r_[0.9, 1.1, 0.5] * k * 0.01 + 1.0), zero[:3]]
        yield inverse_kinematics(robot, x).AT, w


@pytest.mark.parametrize("name, amplitude, push", [("ipanema3_mini", 0.04, 40.0), ("ipanema3", 1.5, 2000.0)])
def test_the_margin_lp_kept_warm_is_the_cold_lp_along_a_guided_path(name, amplitude, push):
    """The force set-point keeps one LP model from period to period (MarginLP, set up once: building
    it anew each period cost about 100 us of the 1 kHz loop); warm-started, it finds the margin of a
    cold solve at every period, also where the wrench leaves none (-inf) and after."""
    robot = load_robot(name)
    f_min, f_max = robot.cable.f_min, robot.cable.f_max
    lp = MarginLP(6, robot.m)
    warm, cold = [], []
    for AT, w in _guided_path(robot, 1500, amplitude, push):
        warm.append(lp.solve(AT, w, f_min, f_max))
        cold.append(largest_margin(AT, w, f_min, f_max))
    assert np.isfinite(cold).sum() > 100 and np.isinf(cold).sum() > 100   # (margins and none along the path)
    np.testing.assert_allclose(warm, cold, atol=1e-6)


def test_the_guided_force_setpoint_sets_its_margin_lp_up_once():
    """The LP of the reserve's margin is set up in the first guided period and then only updated."""
    fs = ForceSetpoint(MINI, DT, control_loop_params(MINI).force)
    _at_rest(fs, MINI, 2, HAND)
    model = fs.margin_lp.model
    _at_rest(fs, MINI, 200, HAND)
    assert model is not None and fs.margin_lp.model is model


def test_the_user_forces_are_the_least_squares_forces():
    AT = inverse_kinematics(MINI, np.r_[0.02, -0.01, 0.01, 0.02, 0.0, -0.03]).AT
    np.testing.assert_allclose(user_forces(AT, HAND), np.linalg.lstsq(AT, HAND, rcond=None)[0], rtol=1e-10)
    AT[5] = 0.0                                                  # rank-deficient: the least-squares fallback
    np.testing.assert_array_equal(user_forces(AT, HAND), np.linalg.lstsq(AT, HAND, rcond=None)[0])


def _pushed_beyond(guided: bool):
    """The force set-point at the sweep's Mini #19 [0.083, 0.186, 0.104] (border), the measured wrench
    that of a 13 N hand along -y, which no cable forces within [f_min, f_max] balance there."""
    x, zero = np.r_[0.0834, 0.1859, 0.1041, 0.0, 0.0, 0.0], np.zeros(6)
    hand = np.r_[0.0, -13.0, 0.0, 0.0, 0.0, 0.0]
    fs = ForceSetpoint(MINI, DT, control_loop_params(MINI).force)
    w = platform_wrench(MINI, x, zero, zero)
    fs.set_user_wrench(None)
    for _ in range(600):
        fs.update(x, zero, zero, w)
    fs.set_user_wrench(hand - np.sign(hand) * 0.5 if guided else None)
    return [fs.update(x, zero, zero, w + hand) for _ in range(1500)]


def test_a_guided_setpoint_the_limits_cannot_hold_is_clipped_to_them():
    """A hand pushing a wrench the pose cannot balance within the limits: the distribution returns
    its least-violating forces (section 3.6.2), above f_max here; while a user guides they are
    clipped to [f_min, f_max] (the platform gives way; the force watch holds on the measured forces),
    the status still says the wrench had no solution. Without a user the distribution is the thesis'."""
    plain = _pushed_beyond(False)[-1]
    assert plain.status != Status.FEASIBLE and plain.f.max() > 40.0 + 1e-3   # the case to clip
    guided = _pushed_beyond(True)
    assert all(r.f.max() <= r.f_max.max() + 1e-12 and r.f.min() >= r.f_min.min() - 1e-12 for r in guided)
    assert guided[-1].status != Status.FEASIBLE


def _held(fs, robot, x, periods, w_user=None):
    """``periods`` periods holding the pose x, the measured wrench the model's, the user's wrench given."""
    zero = np.zeros(6)
    w = platform_wrench(robot, x, zero, zero)
    fs.set_user_wrench(w_user)
    return [fs.update(x, zero, zero, w) for _ in range(periods)]


def test_the_forces_the_reserve_adds_rise_at_the_tension_rate_where_its_null_space_gain_is_large():
    """The IPAnema 3's grid pose #12 [3.487, 3.233, -0.345] (interior): raising the two lowest cables'
    bound by r moves the others along the null space of A^T by many times r. With only r rate-limited,
    f_d rose at up to 58 kN/s there (RESERVE_RING 2), the CFC lagged, the lag read as a user wrench
    that raised r again, and the loop ran into a 13 Hz oscillation until the force watch held. Now
    every cable's set-point moves by at most the tension rate's step per period while r rises, still
    balances the wrench set-point, and ends at the raised QP's optimum."""
    robot = load_robot("ipanema3")
    x = np.r_[3.4869, 3.2332, -0.3452, 0.0, 0.0, 0.0]
    params = control_loop_params(robot).force
    fs = ForceSetpoint(robot, DT, params)
    plain = _held(fs, robot, x, 400)[-1]
    d = fs.distributor
    rate = params.tension_rate * float(np.max(d.f_max - d.f_min))
    hand = np.r_[60.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    AT = inverse_kinematics(robot, x).AT
    r = RESERVE_RING * float(np.abs(user_forces(AT, hand)).max())
    optimum = d.qp.solve(AT, fs.w_d, f_min=d.f_min + r, f_max=d.f_max - r).f
    assert np.abs(optimum - plain.f).max() > 10.0 * r            # the null-space gain this pose has
    results, kept = [], []
    for _ in range(1500):
        results += _held(fs, robot, x, 1, hand)
        kept.append(fs.reserve_applied)
    f = np.array([plain.f] + [res.f for res in results])
    assert np.abs(np.diff(f, axis=0)).max() <= rate * DT * (1.0 + 1e-9)
    for res, r_k in zip(results, kept):
        np.testing.assert_allclose(AT @ res.f, -fs.w_d, atol=1e-6)
        assert res.f.min() >= d.f_min.min() + r_k - 1e-6 and res.f.max() <= d.f_max.max() - r_k + 1e-6
    assert 0.0 < kept[0] < rate * DT / 2.0                       # (the gain slows the reserve, not only f_d)
    assert fs.reserve_applied == pytest.approx(r)
    np.testing.assert_allclose(results[-1].f, optimum, atol=1e-6)

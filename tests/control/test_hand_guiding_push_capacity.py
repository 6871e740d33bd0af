"""What a user can push at a pose (the validation sweep's guiding push, issue 25 decision (a)):
:func:`cdpr_tools.validate.cases.push_scale` scales the nominal push so that the hand's share of
the cable forces, RESERVE_RING times (the release's swing), stays within the hand's reserve the
pose leaves (RESERVE_SHARE of the largest margin t, docs/admittance.md), and a pose that carries
less than PUSH_MIN_SCALE of it is *beyond capacity*, judged on safety (criteria: no cable below 0.5 f_min for > 50 ms while the loop
commands, no force set-point above f_max then, the cables back within their limits within 0.5 s of
the release). Checked against an independent LP (scipy's HiGHS) of the margin."""
import numpy as np
import pytest
from scipy.optimize import linprog

from cdpr_control import kernels
from cdpr_control.control.force_setpoint import RESERVE_RING, RESERVE_SHARE
from cdpr_control.model.robot import load_robot
from cdpr_tools.validate import criteria
from cdpr_tools.validate.cases import PUSH_MIN_SCALE, PushCapacity, hold_is_safe_reaction, push_scale
from cdpr_tools.validate.grid import planned_f_min

MINI = load_robot("ipanema3_mini")
F_MAX = 40.0                   # N, the Mini's f_max (robot file, table 2.2), which its distribution plans with


def margin(robot, x, w) -> float:
    """max t s.t. A^T f = -w, f_min + t <= f <= f_max - t (HiGHS), -inf where infeasible."""
    AT, = kernels.inverse_kinematics_fields(robot, np.asarray(x, dtype=float), "AT")
    f_min, m = planned_f_min(robot), robot.m
    A_ub = np.block([[-np.eye(m), np.ones((m, 1))], [np.eye(m), np.ones((m, 1))]])
    b_ub = np.r_[-f_min, np.full(m, F_MAX)]
    res = linprog(np.r_[np.zeros(m), -1.0], A_ub=A_ub, b_ub=b_ub, A_eq=np.c_[AT, np.zeros(6)], b_eq=-w,
                  bounds=[(None, None)] * m + [(0.0, None)], method="highs")
    return float(res.x[-1]) if res.status == 0 else -np.inf


def share(robot, x, h) -> float:
    AT, = kernels.inverse_kinematics_fields(robot, np.asarray(x, dtype=float), "AT")
    return float(np.abs(np.linalg.pinv(AT) @ h).max())


def weight(robot, x) -> np.ndarray:
    return kernels.platform_wrench(robot, np.asarray(x, dtype=float), np.zeros(6), np.zeros(6))


@pytest.mark.parametrize("x, direction", [
    ([0.0, 0.0, 0.0, 0, 0, 0], (1, 0, 0)),                       # home: the whole push
    ([-0.214, 0.097, 0.022, 0, 0, 0], (1, 1, -1)),               # the sweep's #4 (interior): scaled
    ([-0.073, -0.182, 0.058, 0, 0, 0], (0, -1, 0)),              # #7 (border): scaled
    ([-0.156, -0.185, -0.227, 0, 0, 0], (0, 0, -1)),             # #3 (border): beyond capacity
])
def test_the_push_scale_is_where_the_hands_share_meets_the_reserve(x, direction):
    d = np.asarray(direction, dtype=float)
    h = np.r_[13.0 * d / np.linalg.norm(d), np.zeros(3)]
    cap = push_scale(MINI, x, h)
    w = weight(MINI, x)
    assert cap.share_N == pytest.approx(share(MINI, x, h), rel=1e-9)
    assert cap.margin_N == pytest.approx(margin(MINI, x, w + h), abs=1e-6)
    gap = lambda k: RESERVE_SHARE * margin(MINI, x, w + k * h) - RESERVE_RING * k * cap.share_N  # noqa: E731
    if cap.scale == 1.0:
        assert gap(1.0) >= 0.0
    else:                      # the boundary: within at k, not just above it
        assert 0.0 < cap.scale < 1.0
        assert gap(cap.scale) >= -1e-6 and gap(cap.scale + 1e-3) < 0.0
        for k in np.linspace(0.0, cap.scale, 5):      # and on the whole interval below it (t concave)
            assert gap(k) >= -1e-6
    assert cap.beyond == (cap.scale < PUSH_MIN_SCALE)


def test_home_takes_the_whole_push_and_a_border_pose_pushed_down_is_beyond_capacity():
    h = np.r_[0.0, 0.0, -13.0, 0, 0, 0]
    assert push_scale(MINI, [0.0, 0.0, 0.0, 0, 0, 0], h).scale == 1.0
    cap = push_scale(MINI, [-0.156, -0.185, -0.227, 0, 0, 0], h)
    assert cap.beyond and cap.scale < PUSH_MIN_SCALE


def test_a_pose_without_margin_carries_no_push():
    """Pushed where the pose leaves no margin with the push (the largest margin of w + k h below the
    share for every k > 0): k = 0."""
    x = [0.188, -0.116, 0.168, 0, 0, np.deg2rad(-5.0)]        # the sweep's #26: t 0.08 N without the push
    h = np.r_[0.0, 0.0, 13.0, 0, 0, 0]
    cap = push_scale(MINI, x, h)
    assert cap.scale < 0.05
    assert RESERVE_SHARE * margin(MINI, x, weight(MINI, x) + 0.05 * h) < RESERVE_RING * 0.05 * cap.share_N


def test_safety_criteria_of_a_push_beyond_capacity():
    f = np.full((200, 8), 10.0)
    f[50:100, 3] = 2.4                     # 50 ms below 0.5 f_min (2.5 N): within
    assert criteria.slack_time(f, criteria.SAFETY_SLACK_SHARE * MINI.cable.f_min, 1e-3) == pytest.approx(0.05)
    assert criteria.BANDS["safety_slack_s"].holds(0.05)
    f[100, 3] = 2.4                        # 51 ms: out
    assert not criteria.BANDS["safety_slack_s"].holds(criteria.slack_time(f, 2.5, 1e-3))
    f_d = np.full((10, 8), 39.0)
    assert criteria.above_limit(f_d, 40.0) == -1.0 and criteria.BANDS["setpoint_above_f_max_N"].holds(-1.0)
    f_d[4, 2] = 40.5
    assert criteria.above_limit(f_d, 40.0) == 0.5 and not criteria.BANDS["setpoint_above_f_max_N"].holds(0.5)
    f_d[5, 1] = np.nan                      # a NaN set-point is never within
    assert not criteria.BANDS["setpoint_above_f_max_N"].holds(criteria.above_limit(f_d, 40.0))


def test_slack_counts_only_while_the_loop_commands_and_the_cables_must_recover():
    """The lead's decision (session 11): slack while the loop holds (a hand still pushing a wrench
    the pose cannot balance) is reported, not judged; a run of slack split by the hold is two runs;
    after the release every cable is back within [f_min, f_max] within recovery_s."""
    f = np.full((400, 8), 10.0)
    f[100:300, 2] = 1.0                    # 200 ms below 0.5 f_min
    acting = np.ones(400, dtype=bool)
    assert criteria.slack_time(f, 2.5, 1e-3, where=acting) == pytest.approx(0.2)
    acting[140:400] = False                # held from 40 ms into the slack on
    assert criteria.slack_time(f, 2.5, 1e-3, where=acting) == pytest.approx(0.04)
    assert criteria.slack_time(f, 2.5, 1e-3, where=~acting) == pytest.approx(0.16)
    acting[200:210] = True                 # commanding again for 10 ms within the slack: a second run
    assert criteria.slack_time(f, 2.5, 1e-3, where=acting) == pytest.approx(0.04)
    f_min, f_max = MINI.cable.f_min, MINI.cable.f_max
    assert criteria.recovery_time(f[300:], f_min, f_max, 1e-3) == 0.0
    assert criteria.recovery_time(f[250:], f_min, f_max, 1e-3) == pytest.approx(0.05)
    g = f.copy()
    g[320, 5] = 40.5                       # above f_max later, once: recovered only after it
    assert criteria.recovery_time(g[250:], f_min, f_max, 1e-3) == pytest.approx(0.071)
    g[-1, 0] = 4.9                         # still outside at the end: never recovered
    assert criteria.recovery_time(g[250:], f_min, f_max, 1e-3) == np.inf
    assert criteria.BANDS["recovery_s"].holds(0.5) and not criteria.BANDS["recovery_s"].holds(0.501)


def test_a_hold_passes_only_beyond_capacity_and_only_from_the_push_on():
    beyond, carried = PushCapacity(0.1, 6.0, -np.inf), PushCapacity(0.5, 6.0, 3.0)
    assert beyond.beyond and not carried.beyond
    assert hold_is_safe_reaction(beyond, 1.6, 1.5)            # the force watch during the push
    assert not hold_is_safe_reaction(beyond, 1.2, 1.5)        # held before the push: the start-up, a failure
    assert not hold_is_safe_reaction(beyond, None, 1.5)
    assert not hold_is_safe_reaction(carried, 1.6, 1.5)       # a push the pose carries must not hold

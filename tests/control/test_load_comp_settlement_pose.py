"""The cable settlement (section 4.1.3) in the pose estimator: cause A of docs/load_compensation.md
("The settlement in the pose estimator"). A settled cable is longer than its encoder says at the same
force; the forward kinematics takes θ + s with the load compensation's identified s, and only then
(``settlement_identified``)."""
import numpy as np
import pytest

from cdpr_control.control.load_compensation import (LoadCompensation, LoadCompensationParams,
                                                    LoadCompensationStage)
from cdpr_control.control.pose_estimator import PoseEstimator
from cdpr_control.model import cable
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot

IPANEMA3 = load_robot("ipanema3")


def _winch_lengths(robot, x, f):
    """θ with θ + dq(f, θ) = IK(x).q (the closed form of (3.7), cable.elongation_from_force_and_winch_length)."""
    q = inverse_kinematics(robot, x).q
    k = cable.specific_stiffness(robot, f)
    return (q * (k - f) - f * robot.l_0) / k


def _calibrated(robot, theta, f, x_d):
    est = PoseEstimator(robot, calibration_window=1)
    est.update(theta, f, x_d)                 # the calibration sample: the cables settled to these lengths
    return est


def test_the_pose_estimator_takes_the_settled_lengths():
    """Cables settled by s = J dx0 (J = dq/dx, the platform 5 mm lower and 2 mrad about x at the same
    encoder readings and forces): without s the forward kinematics reads the pose displaced by -dx0
    (the settled platform too high: what the OSPC then holds), with s it reads the pose of the
    unsettled lengths."""
    robot = IPANEMA3
    x = np.r_[0.4, -0.3, 1.0, 0.0, 0.0, 0.0]
    f = np.linspace(800.0, 1500.0, robot.m)
    theta = _winch_lengths(robot, x, f)
    x_d = x                                    # every estimator warm-started (its pulleys frozen) there
    x, _ = _calibrated(robot, theta, f, x_d).update(theta, f, x_d)     # the unsettled reading (its Δq_0: not x_d)
    dx0 = np.r_[0.0, 0.0, -0.005, 0.002, 0.0, 0.0]
    h = 1e-6
    J = np.column_stack([(inverse_kinematics(robot, x + h * e).q - inverse_kinematics(robot, x - h * e).q) / (2 * h)
                         for e in np.eye(6)])
    s = J @ dx0
    encoders = theta - s                      # the encoders do not see the settlement
    blind = _calibrated(robot, theta, f, x_d)
    x_blind, _ = blind.update(encoders, f, x_d)
    # about -dx0 (J here is the full pulley IK's, the estimator's frozen pulleys differ by some %)
    assert np.linalg.norm(x_blind - x + dx0) < 0.15 * np.linalg.norm(dx0)
    seeing = _calibrated(robot, theta, f, x_d)
    seeing.settlement = s
    x_seen, _ = seeing.update(encoders, f, x_d)
    np.testing.assert_allclose(x_seen, x, atol=1e-8)


@pytest.mark.parametrize("ratio, identified, handed", [(0.3, True, True), (0.3, False, False), (0.0, True, False)])
def test_the_settlement_goes_to_the_pose_only_when_identified(ratio, identified, handed):
    """An assumed ratio (the IPAnema 3's shipped 0.15) stays in x_d,LC: it over-compensates a plant
    that does not settle; an identified one also goes to the pose estimator; ratio 0 is off."""
    p = LoadCompensationParams(settlement_ratio=ratio, settlement_identified=identified)
    lc = LoadCompensation(IPANEMA3, 1e-3, p)
    lc.settlement.reset(np.full(IPANEMA3.m, 500.0))
    lc.settlement.update(np.full(IPANEMA3.m, 1500.0), np.full(IPANEMA3.m, 5.0))
    s = lc.pose_settlement()
    if handed:
        assert s is not None and np.all(s > 0.0)
        np.testing.assert_array_equal(s, lc.settlement.s)
        s[:] = 0.0                             # a copy: the estimator cannot change the model
        assert np.all(lc.settlement.s > 0.0)
    else:
        assert s is None
    assert LoadCompensationParams().settlement_identified is False     # the default: off


@pytest.mark.parametrize("identified", [True, False])
def test_the_loop_hands_the_identified_settlement_to_its_pose_estimator(identified):
    """In-process loop (the mismatched plant, IPAnema 3 home under force control, 60 kg put down):
    every period the pose estimator has the load compensation's s of that period (its next
    forward kinematics takes it), None where the ratio was not identified."""
    from cdpr_sim.closed_loop import hold, run

    robot = IPANEMA3
    stage = LoadCompensationStage(robot, 1e-3, LoadCompensationParams(enabled=False, settlement_ratio=0.3,
                                                                      settlement_identified=identified),
                                  feed_force_setpoint=True)
    seen = []

    def step(k, loop, sim):
        if k == 200:
            sim.set_payload(60.0)
        if k > 0:
            seen.append((None if loop.estimator.settlement is None else loop.estimator.settlement.copy(),
                         stage.compensation.settlement.s.copy()))

    run(robot, hold(robot.home), 1.5, x0=robot.home, before_step=step, offset_stages={"load_compensation": stage})
    if identified:
        assert all(given is not None and np.array_equal(given, s) for given, s in seen)
        assert seen[-1][1].max() > 1e-4       # the loaded cables settled by more than 0.1 mm
    else:
        assert all(given is None for given, _ in seen)
        assert seen[-1][1].max() > 1e-4       # the model runs (x_d,LC's), the pose does not take it


@pytest.mark.parametrize("phi", [np.zeros(3), np.r_[0.05, -0.08, 0.3]])
def test_the_settlement_offset_shortens_the_cables_by_s(phi):
    """settlement_offset: for s = J dx0 (a settlement a rigid motion gives), IK(x + offset) = q - s to
    second order; for any s the length error left is the least-squares residual, orthogonal to the
    lengths every pose offset can change (finite differences of the full inverse kinematics)."""
    from cdpr_control.control.load_compensation import settlement_offset

    robot = IPANEMA3
    x = np.r_[0.4, -0.3, 1.0, phi]
    ik = inverse_kinematics(robot, x)
    h = 1e-6
    J = np.column_stack([(inverse_kinematics(robot, x + h * e).q - inverse_kinematics(robot, x - h * e).q) / (2 * h)
                         for e in np.eye(6)])
    s = J @ np.r_[0.001, -0.002, -0.004, 0.001, 0.0005, -0.002]
    dq = inverse_kinematics(robot, x + settlement_offset(ik, s, x[3:])).q - ik.q
    np.testing.assert_allclose(dq, -s, atol=2e-3 * np.abs(s).max())     # second-order rest of 4 mm
    generic = np.linspace(0.5e-3, 3e-3, robot.m)                          # 8 cables, 6 DOF: not all of it
    offset = settlement_offset(ik, generic, x[3:])
    residual = generic + J @ offset
    assert np.linalg.norm(J.T @ residual) < 1e-6 * np.linalg.norm(J.T @ generic)     # (J: differences)


@pytest.mark.parametrize("enabled, identified", [(False, True), (False, False), (True, True)])
def test_force_control_takes_out_an_identified_settlement(enabled, identified):
    """With x_d,LC off (force control) the stage's output is settlement_offset of the model's s where
    the ratio was identified, and active (the joint command adds it); not identified: zero and
    inactive; with x_d,LC on the output is x_d,LC (which holds s through secant_offset)."""
    from cdpr_control.control.load_compensation import settlement_offset
    from cdpr_control.control.loop import LoopInputs

    robot = IPANEMA3
    stage = LoadCompensationStage(robot, 1e-3, LoadCompensationParams(enabled=enabled, settlement_ratio=0.3,
                                                                      settlement_identified=identified))
    lc = stage.compensation
    x_d = robot.home.copy()
    ik = inverse_kinematics(robot, x_d)
    f0 = np.full(robot.m, 600.0)
    zero = np.zeros(6)
    out = None
    for k in range(400):
        f = f0 if k < 100 else f0 + 400.0                 # the cables load up: they settle
        out = stage.offset(LoopInputs(1e-3 * k, x_d, zero, zero, ik.q, f, x_d, -ik.AT @ f))
        if k == 99:
            lc.settlement.reset(lc.force_filter.mean)     # settled to the unloaded forces
    assert lc.settlement.s.max() > 1e-5
    if enabled:
        assert out.active
        np.testing.assert_array_equal(out.x, lc.x_lc)
    elif identified:
        assert out.active
        np.testing.assert_allclose(out.x, settlement_offset(ik, lc.settlement.s, x_d[3:]), atol=1e-12)
        assert out.x[2] > 0.0                             # longer cables: the command lifts the platform
    else:
        assert not out.active and not out.x.any()

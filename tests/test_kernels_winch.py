"""The simulator's compiled winch kernels (cdpr_control.kernels.winch) against the numpy reference.

kernels.friction_sensor_force and kernels.drive_step do the reference's operations in the same
order, element by element: against the reference compiled by numba (cdpr_sim.simulator.compiled,
the simulator's path with the kernels off) they give the same bits; against plain numpy the
exponential of the Dahl model may round differently (numpy's vectorised exp), hence 1e-12 there.
"""
import math

import numpy as np
import pytest

from cdpr_control import kernels, kinematics
from cdpr_control.drive_models import DriveModel
from cdpr_control.friction import PulleyFriction
from cdpr_control.robot import load_robot
from cdpr_sim.simulator import SimConfig, Simulator, compiled

ROBOTS = ("ipanema3_mini", "ipanema3")


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request):
    robot = load_robot(request.param)
    kernels.warm_up(robot)
    return robot


def _friction_inputs(robot, n=700, v_eps=1e-7):
    """Cable velocities through slip, reversal, the standstill band (|v| <= v_eps keeps the last
    direction) and exact standstill, per cable out of phase; forces around the pretension."""
    ik = kinematics.inverse_kinematics(robot, robot.home)
    theta = ik.q.copy()
    m = robot.m
    for k in range(n):
        v = 0.05 * np.sin(k / 40.0 + np.arange(m))
        if 300 <= k < 340:
            v = np.where(np.arange(m) % 2 == 0, 0.5 * v_eps * np.sign(v), v)   # inside the band
        if 500 <= k < 530:
            v = np.zeros(m)
        theta = theta + v * 1e-3
        f = 100.0 + 40.0 * np.sin(k / 25.0 + 2 * np.arange(m))
        yield f, theta, v, ik.beta


def test_friction_sensor_force_equals_the_reference_through_stick_and_slip(robot):
    plain, jitted, fast = (PulleyFriction.from_robot(robot, kinematics.inverse_kinematics(robot, robot.home).q, 1e-7,
                                                     jit=jit) for jit in (None, compiled, None))
    reversals = 0
    for f, theta, v, beta in _friction_inputs(robot):
        last = fast.dahl.last_direction.copy()
        F_s = kernels.friction_sensor_force(fast, f, theta, v, beta)
        np.testing.assert_array_equal(F_s, jitted.sensor_force(f, theta, v, beta))
        np.testing.assert_array_equal(fast.dahl.state, jitted.dahl.state)
        np.testing.assert_allclose(F_s, plain.sensor_force(f, theta, v, beta), rtol=1e-12)
        np.testing.assert_allclose(fast.dahl.state, plain.dahl.state, rtol=1e-12, atol=1e-12)
        reversals += np.count_nonzero((last != 0.0) & (fast.dahl.last_direction != last))
    assert reversals >= 2 * robot.m


@pytest.mark.parametrize("max_iterations", [0, 1, 2, 50])
def test_friction_sensor_force_iteration_limits_and_non_finite_forces(robot, max_iterations):
    """The shared iteration count: cut short after 0, 1, 2 iterations, and a NaN force, which the
    reference never lets stop early (the other cables then iterate to the limit too)."""
    q = kinematics.inverse_kinematics(robot, robot.home).q
    jitted, fast = (PulleyFriction.from_robot(robot, q, 1e-7, jit=jit) for jit in (compiled, None))
    for k, (f, theta, v, beta) in enumerate(_friction_inputs(robot, n=200)):
        if k == 150:
            f = f.copy()
            f[1] = math.nan
        F_s = kernels.friction_sensor_force(fast, f, theta, v, beta, max_iterations=max_iterations)
        np.testing.assert_array_equal(F_s, jitted.sensor_force(f, theta, v, beta, max_iterations=max_iterations))
        np.testing.assert_array_equal(fast.dahl.state, jitted.dahl.state)


def test_friction_sensor_force_at_the_first_motion_and_with_a_standstill_band_of_zero(robot):
    """From standstill (direction 0) the first sample moves some cables and leaves others at rest;
    with v_eps = 0 any speed is motion."""
    q = kinematics.inverse_kinematics(robot, robot.home).q
    beta = kinematics.inverse_kinematics(robot, robot.home).beta
    for v_eps in (0.0, 1e-3):
        jitted, fast = (PulleyFriction.from_robot(robot, q, v_eps, jit=jit) for jit in (compiled, None))
        v = np.where(np.arange(robot.m) % 3 == 0, 0.0, np.where(np.arange(robot.m) % 3 == 1, 2e-3, -2e-3))
        theta, f = q.copy(), np.full(robot.m, 80.0)
        for _ in range(5):
            theta = theta + v * 1e-3
            np.testing.assert_array_equal(kernels.friction_sensor_force(fast, f, theta, v, beta),
                                          jitted.sensor_force(f, theta, v, beta))
            np.testing.assert_array_equal(fast.dahl.state, jitted.dahl.state)


def _drives(robot, jit=None):
    """The robot's drive model and, for the other kind, the same robot's drive as PT1 with a pure
    or fractional dead time and as a slow second order; all with a speed limit that large steps hit."""
    d = robot.drive
    yield DriveModel.from_robot(robot, 1e-3, jit)
    yield DriveModel.pt1_deadtime(0.0, 0.0025, 1e-3, robot.m, 0.5, jit)
    yield DriveModel.pt1_deadtime(0.004, 0.0013, 1e-3, robot.m, 0.5, jit)
    yield DriveModel.second_order(0.01, 0.7, 0.002, 1e-3, robot.m, 0.5, jit)
    yield DriveModel.second_order(0.01, 0.7, 0.0, 1e-3, robot.m, d.v_max, jit)


def test_drive_step_equals_the_reference_through_the_speed_limit(robot):
    rng = np.random.default_rng(4)
    for plain, jitted, fast in zip(_drives(robot), _drives(robot, compiled), _drives(robot)):
        for drive in (plain, jitted, fast):
            drive.reset(np.full(robot.m, 2.0))
        limited = 0
        for k in range(400):
            u = 2.0 + 0.01 * np.sin(0.05 * k + np.arange(robot.m))
            if k in (100, 250):
                u = u + rng.uniform(-2.0, 2.0, robot.m)                 # steps beyond v_max dt
            theta = kernels.drive_step(fast, u)
            assert theta is fast.theta
            np.testing.assert_array_equal(theta, jitted.step(u))
            np.testing.assert_array_equal(fast.thetadot, jitted.thetadot)
            np.testing.assert_array_equal(fast.x, jitted.x)
            assert fast.head == jitted.head
            np.testing.assert_allclose(theta, plain.step(u), rtol=1e-13, atol=1e-15)
            np.testing.assert_allclose(fast.thetadot, plain.thetadot, rtol=1e-12, atol=1e-12)
            limited += bool(np.isclose(np.abs(fast.thetadot).max(), fast.v_max))
        assert limited > 0


def test_drive_step_returns_a_new_array_and_keeps_the_last_one():
    """The simulator keeps the last period's theta while the drives step on: a fresh array a step."""
    robot = load_robot("ipanema3_mini")
    drive = DriveModel.from_robot(robot, 1e-3)
    drive.reset(np.ones(robot.m))
    first = kernels.drive_step(drive, np.full(robot.m, 1.1))
    before = first.copy()
    second = kernels.drive_step(drive, np.full(robot.m, 1.2))
    assert second is not first
    np.testing.assert_array_equal(first, before)


def test_drive_step_without_limit_and_with_a_non_finite_command():
    """A NaN command: the reference's largest step is NaN, no cable is limited; the NaN cable goes
    NaN and the others step as usual."""
    robot = load_robot("ipanema3")
    jitted, fast = DriveModel.from_robot(robot, 1e-3, jit=compiled), DriveModel.from_robot(robot, 1e-3)
    for drive in (jitted, fast):
        drive.reset(np.zeros(robot.m))
    u = np.full(robot.m, 1.0)
    u[2] = math.nan
    for _ in range(3):
        np.testing.assert_array_equal(kernels.drive_step(fast, u), jitted.step(u))
        np.testing.assert_array_equal(fast.thetadot, jitted.thetadot)


def test_the_wrappers_refuse_arrays_of_another_length():
    """The compiled loops index without bounds checks: a wrong length is refused before them."""
    robot = load_robot("ipanema3")
    q = kinematics.inverse_kinematics(robot, robot.home).q
    friction, drive = PulleyFriction.from_robot(robot, q, 1e-7), DriveModel.from_robot(robot, 1e-3)
    state = friction.dahl.state.copy()
    short, ones, zeros = np.ones(robot.m - 1), np.ones(robot.m), np.zeros(robot.m)
    for args in ((short, q, zeros), (ones, short, zeros), (ones, q, short)):
        with pytest.raises(ValueError):
            kernels.friction_sensor_force(friction, *args, ones)
    np.testing.assert_array_equal(friction.dahl.state, state)
    with pytest.raises(ValueError):
        kernels.drive_step(drive, np.ones(robot.m + 1))


def test_the_simulator_runs_the_kernels_and_the_reference_gives_the_same_bits(monkeypatch):
    """Simulator.step: the kernels when ENABLED, the models' own methods under numpy_reference();
    the outputs of the two runs are identical."""
    robot = load_robot("ipanema3_mini")
    calls = []
    for cls, name in ((DriveModel, "step"), (PulleyFriction, "sensor_force")):
        original = getattr(cls, name)
        monkeypatch.setattr(cls, name,
                            lambda self, *a, _f=original, _n=name, **kw: calls.append(_n) or _f(self, *a, **kw))
    runs = []
    for enabled in (True, False):
        calls.clear()
        rows = []
        with Simulator(robot, SimConfig(), x0=robot.home) as sim:
            theta0 = sim.drives.theta.copy()
            for k in range(300):
                u = theta0 + 0.01 * np.sin(2 * np.pi * k * 1e-3 + np.arange(robot.m))
                if enabled:
                    out = sim.step(u)
                else:
                    with kernels.numpy_reference():
                        out = sim.step(u)
                rows.append(np.concatenate((out.F_s_true, out.theta_true, out.thetadot, out.x, out.f)))
        runs.append(np.array(rows))
        assert set(calls) == (set() if enabled else {"step", "sensor_force"})
    np.testing.assert_array_equal(runs[0], runs[1])

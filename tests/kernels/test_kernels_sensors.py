"""The simulator's compiled sensor friction (cdpr_control.kernels.friction) against the numpy reference.

kernels.friction_sensor_force does the operations of PulleyFriction.sensor_force in the same order,
element by element: against the reference compiled by numba (cdpr_sim.simulator.compiled, the
simulator's path with the kernels off) it gives the same bits; against plain numpy the exponential
of the Dahl model may round differently (numpy's vectorised exp), hence 1e-12 there.
"""
import math

import numpy as np
import pytest

from cdpr_control import kernels
from cdpr_control.model import kinematics
from cdpr_control.model.friction import PulleyFriction
from cdpr_control.model.robot import load_robot
from cdpr_sim.simulator import SimConfig, Simulator, compiled


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


def test_friction_sensor_force_refuses_arrays_of_another_length():
    """The compiled loops index without bounds checks: a wrong length is refused before them."""
    robot = load_robot("ipanema3")
    q = kinematics.inverse_kinematics(robot, robot.home).q
    friction = PulleyFriction.from_robot(robot, q, 1e-7)
    state = friction.dahl.state.copy()
    short, ones, zeros = np.ones(robot.m - 1), np.ones(robot.m), np.zeros(robot.m)
    for args in ((short, q, zeros), (ones, short, zeros), (ones, q, short)):
        with pytest.raises(ValueError):
            kernels.friction_sensor_force(friction, *args, ones)
    np.testing.assert_array_equal(friction.dahl.state, state)


def test_the_simulator_runs_the_kernel_and_the_reference_gives_the_same_bits(monkeypatch):
    """Simulator.step: the kernel when ENABLED, PulleyFriction.sensor_force under numpy_reference();
    the outputs of the two runs are identical."""
    robot = load_robot("ipanema3_mini")
    calls = []
    original = PulleyFriction.sensor_force
    monkeypatch.setattr(PulleyFriction, "sensor_force",
                        lambda self, *a, **kw: calls.append(1) or original(self, *a, **kw))
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
        assert (len(calls) == 0) == enabled
    np.testing.assert_array_equal(runs[0], runs[1])

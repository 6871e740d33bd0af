"""The start ramp (docs/control.md, "A start ramp"): the joint command takes the controllers'
command over from the lengths at power-on along :class:`cdpr_control.control.bumpless.StartRamp`,
the cable force controller's set-point rises from the forces measured then at a bounded rate.

At a border pose of the Mini on the default mismatched plant (seed 2), the plant's power-on tension is
up to 10 N from what the controllers command. Without the ramp the shipped force control drove a cable
to 48.8 N (f_max 40 N) within 40 ms and the force watch held.
"""
import dataclasses

import numpy as np
import pytest

from cdpr_control import kernels
from cdpr_control.control import loop
from cdpr_control.control.bumpless import START_FORCE_RANGE_TIME, StartRamp
from cdpr_control.control.cable_force_control import CableForceControl, CFCParams
from cdpr_control.control.params import control_loop_params
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import hold, run
from cdpr_sim.simulator import SimConfig

X_BORDER = np.array([-0.06282650359758432, -0.2046132279102765, -0.011790125856625614, 0.0, 0.0, 0.0])
TOLERANCE = 1.75          # N, the force watch's band beyond the limits (SafetyConfig default)


@pytest.fixture(scope="module")
def robot():
    return load_robot("ipanema3_mini")


def _start(robot, mode: str, **params):
    params = dataclasses.replace(control_loop_params(robot), mode=mode, **params)
    return run(robot, hold(X_BORDER), 1.0, params=params, x0=X_BORDER,
               config=SimConfig(plant="mismatched", plant_seed=2))


def _holds(r) -> list:
    return [f"{r.t[k]:.3f} {f.code}" for k, faults in enumerate(r.faults) for f in faults if f.holds]


def test_force_control_starts_at_a_border_pose_within_the_limits(robot):
    r = _start(robot, "force_control")
    assert not _holds(r), _holds(r)
    assert r.f.max() <= robot.cable.f_max.max() + TOLERANCE
    assert r.f.min() >= robot.cable.f_min.min() - TOLERANCE
    assert np.abs(r.f[-1] - r.f_d[-1]).max() < 1.0          # the CFC has its set-point after 1 s


def test_without_the_ramp_the_same_start_overshoots(robot, monkeypatch):
    """The case the ramp is for: without it (the rate limit alone) the force watch holds."""
    monkeypatch.setattr(loop, "CableForceControl",
                        lambda *args, **kwargs: CableForceControl(*args, **{**kwargs, "start_ramp": False}))
    r = _start(robot, "force_control", start_ramp=0.0)
    assert r.f.max() > robot.cable.f_max.max() + TOLERANCE
    assert any("force_watch" in h for h in _holds(r))


def test_start_ramp_share_is_a_cosine_from_0_to_1():
    ramp = StartRamp(0.01, 0.001)
    shares = [ramp.share() for _ in range(12)]
    expected = [0.5 - 0.5 * np.cos(np.pi * k / 10) for k in range(1, 10)] + [1.0] * 3
    np.testing.assert_allclose(shares, expected, atol=1e-15)
    assert not ramp.running and not StartRamp(0.0, 0.001).running
    for bad in (-1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="start ramp"):
            StartRamp(bad, 0.001)


@pytest.mark.parametrize("compiled", [False, True])
def test_cfc_set_point_rises_from_the_measured_forces_at_the_force_range_rate(robot, compiled, monkeypatch):
    """K_p = 0 (no PI output): f_c,out is the set-point itself, rising from the measured f_0 by at
    most (f_max - f_min) dt / START_FORCE_RANGE_TIME per period until it has caught up with f_d,
    then f_d; the same through the stage's period law (compiled where the kernels are) as through
    the controller's update."""
    if not compiled:
        monkeypatch.setattr(kernels, "ENABLED", False)
    dt = 0.001
    stage = CableForceControl(robot, dt, CFCParams(K_p=0.0), start_ramp=True)
    theta = kernels.cable_lengths(robot, robot.home)
    c = robot.cable
    step = (c.f_max - c.f_min) * dt / START_FORCE_RANGE_TIME
    f_0 = np.linspace(10.0, 20.0, robot.m)
    f_d = f_0 + np.linspace(-20.0, 20.0, robot.m) * step        # cable k catches up after |k - 3.5| * ... periods
    f_ref, outputs, expected = f_0.copy(), [], []
    for _ in range(25):
        stage.update(f_d, f_0, theta, c.f_min, c.f_max)
        outputs.append(stage.controller.f_out.copy())
        lag = f_d - f_ref
        f_ref = f_d.copy() if np.all(np.abs(lag) <= step) else f_ref + np.clip(lag, -step, step)
        expected.append(f_ref.copy())
    np.testing.assert_allclose(outputs, expected, atol=1e-12)
    np.testing.assert_allclose(outputs[-1], f_d, atol=1e-12)
    assert np.all(np.abs(np.diff(np.array([f_0] + outputs), axis=0)) <= step + 1e-12)


def test_cfc_ramps_only_at_its_first_reset(robot):
    """A later reset (a new home calibration, as ControlLoop.set_home_calibration makes one) restarts
    no ramp: the set-point is f_d at once."""
    stage = CableForceControl(robot, 0.001, CFCParams(K_p=0.0), start_ramp=True)
    theta = kernels.cable_lengths(robot, robot.home)
    f_0, f_d = np.full(robot.m, 10.0), np.full(robot.m, 20.0)
    c = robot.cable
    stage.update(f_d, f_0, theta, c.f_min, c.f_max)
    assert np.all(stage.controller.f_out < 11.0)
    stage.controller.dq_0 = None
    stage.update(f_d, f_0, theta, c.f_min, c.f_max)
    np.testing.assert_allclose(stage.controller.f_out, f_d)

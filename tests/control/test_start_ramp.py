"""The start ramp of the joint command in the closed loop (docs/control.md, "A start ramp").

At a border pose of the Mini on the default mismatched plant (seed 2), the plant's power-on tension is
up to 10 N from what the controllers command. Without the ramp the shipped force control drove a cable
to 48.8 N (f_max 40 N) within 40 ms and the force watch held.
"""
import dataclasses

import numpy as np
import pytest

from cdpr_control.control.params import control_loop_params
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import hold, run
from cdpr_sim.simulator import SimConfig

X_BORDER = np.array([-0.06282650359758432, -0.2046132279102765, -0.011790125856625614, 0.0, 0.0, 0.0])
TOLERANCE = 1.75          # N, the force watch's band beyond the limits (SafetyConfig default)


@pytest.fixture(scope="module")
def robot():
    return load_robot("ipanema3_mini")


def _start(robot, mode: str, transfer_time: float | None = None):
    params = dataclasses.replace(control_loop_params(robot), mode=mode)
    if transfer_time is not None:
        params = dataclasses.replace(params, transfer_time=transfer_time)
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


def test_without_the_ramp_the_same_start_overshoots(robot):
    """The case the ramp is for: with transfer_time 0 (no ramp, the rate limit alone) the force watch holds."""
    r = _start(robot, "force_control", transfer_time=0.0)
    assert r.f.max() > robot.cable.f_max.max() + TOLERANCE
    assert any("force_watch" in h for h in _holds(r))

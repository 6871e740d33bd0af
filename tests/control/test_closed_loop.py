"""The control architecture of Fig. 3.4 closed around the simulator (issue: closed loop).

Runs the same stage objects as the nodes (cdpr_control.control.loop) against the pybullet
simulator in one process: stability of both robots in both controller modes, the static pose
error with force control under payloads the controller does not know (the elastic forward
kinematics sees the sag, the OSPC removes it), the straight line to the workspace border of
section 4.2.3, and a live change of the tension level.
"""
import numpy as np
import pytest

from cdpr_control.control.loop import ControlLoopParams
from cdpr_control.control.force_setpoint import ForceSetpointParams
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import hold, run
from cdpr_sim.simulator import SimConfig

ROBOTS = {"ipanema3_mini": load_robot("ipanema3_mini"), "ipanema3": load_robot("ipanema3")}


def _pose_error_mm(r, k=-1):
    return 1e3 * np.linalg.norm(r.x[k, :3] - r.x_d[k, :3])


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("mode", ["force_control", "ik_only"])
def test_holds_home_stably_within_force_limits(name, mode):
    robot = ROBOTS[name]
    r = run(robot, hold(robot.home), 1.5, ControlLoopParams(mode=mode), tension_level=0.0)
    assert np.all(np.isfinite(r.x)) and np.all(np.isfinite(r.f))
    assert _pose_error_mm(r) < 0.1
    settled = r.f[500:]                                    # after the start-up transient
    tol = 0.05 * (robot.cable.f_max - robot.cable.f_min)
    assert np.all(settled >= robot.cable.f_min - tol) and np.all(settled <= robot.cable.f_max)
    # still: the last 0.5 s move less than 10 um
    assert np.ptp(r.x[-500:, :3], axis=0).max() < 1e-5


def _move(x_a, x_b, T):
    """Set-points of a smooth (cosine) move from x_a to x_b in T seconds, then held."""
    def source(t):
        u = min(t / T, 1.0)
        s = 0.5 * (1.0 - np.cos(np.pi * u))
        v = 0.5 * np.pi / T * np.sin(np.pi * u) if u < 1.0 else 0.0
        return x_a + s * (x_b - x_a), v * (x_b - x_a), np.zeros(6)
    return source


# The Mini at home without a payload is not among them: that is test_holds_home_stably_within_force_limits
# [force_control-ipanema3_mini] (the same loop on the default plant, within 0.1 mm); on the nominal plant
# it is the model itself (0.0004 mm after 6 s), and no cable carries more than at power-on, so the
# plant's settlement has nothing to add.
CASES = [
    ("ipanema3_mini", [0.1, 0.05, 0.05], 0.5), ("ipanema3_mini", [-0.1, -0.05, -0.05], 0.5),
    ("ipanema3", [0.0, 0.0, 0.0], 40.0), ("ipanema3", [1.0, 1.0, 0.5], 0.0), ("ipanema3", [-1.0, 0.5, -0.2], 40.0),
]


@pytest.mark.parametrize("name, offset, payload", CASES)
def test_static_pose_error_with_force_control_below_1mm_on_the_perfect_model(name, offset, payload):
    """From home (where the encoders were calibrated, 2.3.2) to the pose in 1.5 s, then held. The
    perfect-model plant: this checks that the loop's equations remove the elastic sag of an
    unknown payload when the model is right (on a real robot geometry errors add to it)."""
    robot = ROBOTS[name]
    x_d = robot.home + np.r_[offset, np.zeros(3)]
    r = run(robot, _move(robot.home, x_d, 1.5), 6.0, ControlLoopParams(), payload=payload,
            config=SimConfig(plant="nominal"))
    assert _pose_error_mm(r) <= 1.0
    assert np.linalg.norm(np.rad2deg(r.x[-1, 3:] - x_d[3:])) < 0.1


@pytest.mark.parametrize("name, offset, payload", CASES)
def test_static_pose_error_with_force_control_on_the_mismatched_plant(name, offset, payload):
    """The same on the default plant, whose geometry is off by up to 3 mm (Mini 2 mm), its sensors
    by 1 % and its cables settle (cdpr_sim/plants/mismatch.yaml): the error is what the model
    cannot see, a few millimetres (measured up to 4.8 mm, 0.12 deg; the thesis measured 50 mm and
    2 deg on the real IPAnema 3, section 4.2.2)."""
    robot = ROBOTS[name]
    x_d = robot.home + np.r_[offset, np.zeros(3)]
    r = run(robot, _move(robot.home, x_d, 1.5), 6.0, ControlLoopParams(), payload=payload)
    assert _pose_error_mm(r) <= 10.0
    assert np.linalg.norm(np.rad2deg(r.x[-1, 3:] - x_d[3:])) < 0.5


def test_straight_line_to_the_border_section_4_2_3():
    """IK only: a cable falls below f_min near the border; force control keeps all within limits."""
    robot = ROBOTS["ipanema3_mini"]
    line = _move(robot.home, robot.home + np.array([0.40, 0, 0, 0, 0, 0]), 2.0)   # QP border: x = 0.42 m
    ik = run(robot, line, 3.0, ControlLoopParams(mode="ik_only"))
    fc = run(robot, line, 3.0, ControlLoopParams(mode="force_control"))
    f_min, f_max = robot.cable.f_min, robot.cable.f_max
    assert ik.f.min() < f_min.min() - 2.0               # slack cable with the rigid model
    # 0.6 N: the plant's force sensors read up to 0.28 N offset and 1 % gain off (mismatch.yaml)
    assert fc.f.min() >= f_min.min() - 0.6 and fc.f.max() <= f_max.max()
    assert _pose_error_mm(fc) < 2.0


def test_tension_level_changed_live_moves_internal_forces_not_the_pose():
    robot = ROBOTS["ipanema3_mini"]

    def schedule(k, loop, sim):
        if k in (1000, 3000):
            p = loop.force.params
            # 0.9 with the shipped parameters: at 1.0 the true forces stay 2-3 N above the Mini's
            # 40 N for seconds, and with the dataclass defaults they fall to 2.2 N on the way back;
            # the force watch (docs/control.md, "Safety") rightly holds both
            loop.force.set_params(ForceSetpointParams(**{**p.__dict__, "tension_level": 0.9 if k == 1000 else 0.0}))

    r = run(robot, hold(robot.home), 5.0, None, before_step=schedule)
    low, high, back = r.f[990], r.f[2990], r.f[-1]
    assert high.mean() > 2.0 * low.mean()               # internal forces follow f_ref from f_min to f_max
    np.testing.assert_allclose(back, low, atol=0.3)
    dev = 1e3 * np.linalg.norm(r.x[:, :3] - r.x_d[:, :3], axis=1)
    assert dev.max() < 1.0                              # the pose moves less than 1 mm throughout


def _param_file(name: str) -> dict:
    import yaml
    from importlib import resources

    return yaml.safe_load(resources.files("cdpr_control").joinpath("params", f"{name}.yaml").read_text())


def test_cable_forces_stay_within_limits_on_the_cuboid_program():
    """The main job's program with the Mini's parameter file: all true cable forces within limits."""
    from cdpr_control import programs
    from cdpr_control.motion.gcode import parse_gcode
    from cdpr_control.motion.interpolation import Interpolator
    from cdpr_sim.closed_loop import program

    robot = ROBOTS["ipanema3_mini"]
    fd = _param_file("ipanema3_mini")["force_distribution"]["ros__parameters"]
    interp = Interpolator(parse_gcode(programs.read("cuboid_mini"), start_pose=robot.home), dt=1e-3)
    params = ControlLoopParams(force=ForceSetpointParams(f_min=np.asarray(fd["f_min"]), tension_level=fd["tension_level"]))
    r = run(robot, program(interp), interp.duration + 0.2, params)
    assert r.f.min() >= robot.cable.f_min.min() and r.f.max() <= robot.cable.f_max.max()
    np.testing.assert_allclose(r.x[-1, :3], r.x_d[-1, :3], atol=1e-3)      # ends at the end point

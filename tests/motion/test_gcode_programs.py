"""The sample programs (cdpr_control/programs/*.gcode) interpolate continuously within the limits,
keep arcs on their circles and end exactly at the programmed end point."""
from functools import lru_cache

import numpy as np
import pytest

from cdpr_control import programs
from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.path import ArcSegment
from cdpr_control.motion.program import Motion
from cdpr_control.motion.interpolation import Limits, ProgramState, sample_program

DT = 1e-3
LIMITS = Limits()
GROUPS = ((slice(0, 3), LIMITS.translation), (slice(3, 6), LIMITS.rotation))


@lru_cache(maxsize=None)
def sample(name):
    program = parse_gcode(programs.read(name))
    return program, sample_program(program, LIMITS, DT)


@pytest.fixture(params=programs.names())
def sampled(request):
    return (request.param, *sample(request.param))


def test_the_expected_samples_ship():
    assert {"rectangle.gcode", "cuboid_mini.gcode", "circle_load_identification.gcode",
            "cylinder_contact_force.gcode"} <= set(programs.names())


def test_continuous_and_within_limits(sampled):
    _, _, s = sampled
    for cols, lim in GROUPS:
        assert np.max(np.linalg.norm(np.diff(s.x[:, cols], axis=0), axis=1)) <= lim.velocity * DT * (1 + 1e-9)
        assert np.max(np.linalg.norm(s.xdd[:, cols], axis=1)) <= lim.acceleration * (1 + 1e-9)
        jerk = np.linalg.norm(np.diff(s.xdd[:, cols], axis=0), axis=1) / DT
        assert np.max(jerk) <= lim.jerk * (1 + 1e-6)
    force_rate = np.linalg.norm(np.diff(s.force, axis=0), axis=1) / DT
    assert np.max(force_rate) <= LIMITS.force.velocity * (1 + 1e-9)


def test_arcs_stay_on_the_programmed_circle(sampled):
    _, program, s = sampled
    for block in program.blocks:
        if isinstance(block, Motion) and isinstance(block.segment, ArcSegment):
            arc = block.segment
            rel = s.x[s.line == block.line, :3] - arc.centre
            normal = rel @ arc.n
            radius = np.linalg.norm(rel - np.outer(normal, arc.n), axis=1)
            assert np.max(np.abs(radius - arc.r0)) < 1e-6
            assert np.max(np.abs(normal)) < 1e-6  # no helix in the samples


def test_last_setpoint_is_the_programmed_end_point(sampled):
    _, program, s = sampled
    assert s.state[-1] is ProgramState.DONE
    np.testing.assert_array_equal(s.x[-1], program.end_pose)
    np.testing.assert_array_equal(s.force[-1], program.end_force)
    assert np.all(s.xd[-1] == 0) and np.all(s.xdd[-1] == 0)


def test_samples_stay_in_the_workspace_of_their_robot(sampled):
    """Programs named *_ipanema3 are for the IPAnema 3 (its workspace box), the others for the Mini."""
    name, _, s = sampled
    if name.endswith("_ipanema3.gcode"):
        from cdpr_control.model.robot import load_robot

        robot = load_robot("ipanema3")
        assert np.all(s.x[:, :3] >= robot.workspace_min) and np.all(s.x[:, :3] <= robot.workspace_max)
        return
    assert np.all(np.abs(s.x[:, 0]) <= 0.15 + 1e-12)
    assert np.all(np.abs(s.x[:, 1:3]) <= 0.1 + 1e-12)


def test_circle_runs_at_constant_speed_between_its_first_and_last_turn():
    program, s = sample("circle_load_identification.gcode")
    arc = next(b for b in program.blocks if isinstance(b, Motion) and isinstance(b.segment, ArcSegment))
    t = s.t[s.line == arc.line]
    middle = (s.line == arc.line) & (s.t > t[0] + 2.0) & (s.t < t[-1] - 2.0)  # 0.5 Hz: one turn = 2 s
    speed = np.linalg.norm(s.xd[middle, :3], axis=1)
    np.testing.assert_allclose(speed, 2 * np.pi * 0.1 * 0.5, rtol=1e-3)  # (4.2): v = r_c dtheta_c


def test_cylinder_program_presses_along_the_surface_normal():
    _, s = sample("cylinder_contact_force.gcode")
    axis = np.array([0.0, -0.28])  # barrel axis (y, z)
    pressing = np.linalg.norm(s.force, axis=1) > 49.0
    rel = s.x[pressing][:, 1:3] - axis
    on_surface = np.abs(np.linalg.norm(rel, axis=1) - 0.2) < 1e-6
    assert on_surface.all()
    normal = rel / np.linalg.norm(rel, axis=1)[:, None]
    force_dir = s.force[pressing][:, 1:] / np.linalg.norm(s.force[pressing][:, 1:], axis=1)[:, None]
    assert np.min(np.sum(force_dir * -normal, axis=1)) > np.cos(np.radians(4))  # within one half arc step
    assert [c.parameter for c in s.commands] == ["enabled", "enabled"]

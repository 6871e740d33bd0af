"""The geometry of the 3D view (cdpr_control.scene) against the kinematics it draws: leave points
on the pulley circles (2.8), platform points (2.1), force colours against the limits (2.39)."""
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from cdpr_control import scene as sc
from cdpr_control.kinematics import inverse_kinematics, rotation_matrix
from cdpr_control.robot import load_robot


@pytest.fixture(params=["ipanema3_mini", "ipanema3"])
def robot(request):
    return load_robot(request.param)


def pose(robot):
    return robot.home + np.array([0.05, -0.03, 0.02, 0.04, -0.03, 0.1]) * np.r_[robot.frame_size, 1, 1, 1] / 2


def test_cables_run_from_the_pulley_leave_points_to_the_platform_points(robot):
    x = pose(robot)
    view = sc.scene(robot, x)
    B = x[:3] + (rotation_matrix(x[3:]) @ robot.b.T).T  # (2.1)
    np.testing.assert_allclose(view.cables[:, 1], B, atol=1e-12)
    np.testing.assert_allclose(view.cables[:, 0], inverse_kinematics(robot, x).c, atol=1e-12)
    length = np.linalg.norm(view.cables[:, 1] - view.cables[:, 0], axis=1)
    np.testing.assert_allclose(length, inverse_kinematics(robot, x).l_f, rtol=1e-12)  # free length (2.5)


def test_pulley_circles_pass_through_anchor_and_leave_point(robot):
    x = pose(robot)
    view = sc.scene(robot, x)
    if not robot.swivelling_pulleys:
        assert view.pulley_edges.shape == (0, 2, 3)
        return
    edges = view.pulley_edges.reshape(robot.m, sc.PULLEY_SEGMENTS, 2, 3)
    np.testing.assert_allclose(edges[:, 0, 0], robot.a, atol=1e-12)  # the swivel axis touches the circle at a_i
    np.testing.assert_allclose(edges[:, -1, 1], robot.a, atol=1e-12)  # closed
    c = inverse_kinematics(robot, x).c
    for i in range(robot.m):
        centre = edges[i, :, 0].mean(axis=0)
        np.testing.assert_allclose(np.linalg.norm(edges[i, :, 0] - centre, axis=1), robot.r_p[i], rtol=1e-9)
        assert abs(np.linalg.norm(c[i] - centre) - robot.r_p[i]) < 1e-9  # C_i on the circle (2.8)
        normal = np.cross(edges[i, 1, 0] - centre, edges[i, 2, 0] - centre)
        assert abs(np.dot(c[i] - centre, normal / np.linalg.norm(normal))) < 1e-9  # in the pulley plane


def test_frame_box_and_platform_hull(robot):
    view = sc.scene(robot, pose(robot))
    assert view.frame_edges.shape == (12, 2, 3)
    sides = np.sort(np.linalg.norm(view.frame_edges[:, 1] - view.frame_edges[:, 0], axis=1))
    size = np.ptp(robot.a, axis=0)
    np.testing.assert_allclose(sides, np.sort(np.repeat(size, 4)), rtol=1e-12)
    tri = view.platform_triangles
    centre = tri.reshape(-1, 3).mean(axis=0)
    volume = sum(abs(np.linalg.det(t - centre)) / 6 for t in tri)
    np.testing.assert_allclose(volume, ConvexHull(robot.b).volume, rtol=1e-9)  # the hull, rotated and moved


def test_force_levels_and_colours_against_the_limits(robot):
    f_min, f_max = robot.cable.f_min, robot.cable.f_max
    f = f_min + np.linspace(0.0, 1.0, robot.m) * (f_max - f_min)
    level = sc.scene(robot, pose(robot), f=f).force_level
    np.testing.assert_allclose(level, np.linspace(0.0, 1.0, robot.m), atol=1e-12)
    assert sc.force_colour(0.0) == (0.0, 0.0, 1.0)
    assert sc.force_colour(0.5) == (0.0, 1.0, 0.0)
    assert sc.force_colour(1.0) == (1.0, 0.0, 0.0)
    assert sc.force_colour(-0.01) == sc.force_colour(1.01) == (1.0, 0.0, 1.0)  # a violated limit
    assert sc.force_colour(float("nan")) == (0.6, 0.6, 0.6)
    assert np.all(np.isnan(sc.scene(robot, pose(robot)).force_level))


def test_wrench_arrow_scale(robot):
    x = pose(robot)
    w = np.r_[np.mean(robot.cable.f_max), 0.0, 0.0, 0.0, 0.0, 0.0]
    arrow = sc.scene(robot, x, w=w).force_arrow
    np.testing.assert_allclose(arrow[0], x[:3])
    np.testing.assert_allclose(np.linalg.norm(arrow[1] - arrow[0]), 0.1 * np.linalg.norm(robot.frame_size), rtol=1e-12)
    np.testing.assert_allclose(sc.scene(robot, x, w=w, force_scale=0.01).force_arrow[1], x[:3] + [0.01 * w[0], 0, 0])

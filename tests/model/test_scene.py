"""The geometry of the 3D view (cdpr_control.model.scene) against the kinematics it draws: leave points
on the pulley circles (2.8), platform points (2.1), force colours against the limits (2.39)."""
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from cdpr_control.model import scene as sc
from cdpr_control.model.kinematics import inverse_kinematics, rotation_matrix


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


def test_pulley_wheels_touch_the_swivel_axis_at_a_and_release_the_cable_at_c(robot):
    x = pose(robot)
    view = sc.scene(robot, x)
    if not robot.swivelling_pulleys:
        assert view.pulley_centres.shape == (0, 3)
        return
    ik = inverse_kinematics(robot, x)
    for centre, normal, r_p, a, c, u in zip(view.pulley_centres, view.pulley_normals, view.pulley_radii,
                                            robot.a, ik.c, ik.u):
        np.testing.assert_allclose(np.linalg.norm(normal), 1.0, rtol=1e-12)
        for point in (a, c):  # on the rim: at r_p from the centre, in the wheel's plane
            np.testing.assert_allclose(np.linalg.norm(point - centre), r_p, rtol=1e-9)
            assert abs(np.dot(point - centre, normal)) < 1e-12
        assert abs(np.dot(c - centre, u)) < 1e-9 * r_p  # the cable leaves tangentially (2.8)


@pytest.mark.parametrize("n", [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0.3, -0.5, 0.8)])
def test_quaternion_takes_the_cylinder_axis_to_the_pulley_normal(n):
    q = sc.z_to(n)
    np.testing.assert_allclose(np.linalg.norm(q), 1.0, rtol=1e-12)
    x, y, z, w = q
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    np.testing.assert_allclose(R[:, 2], np.asarray(n) / np.linalg.norm(n), atol=1e-12)


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

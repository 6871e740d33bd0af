"""Wrench-feasible workspace (2.39)-(2.40): the sets of the methods (W_CF within W_ACF within
W_QP), the exact membership test against DAQP, the grid trajectory, the hull and the plot."""
import numpy as np
import pytest

from cdpr_control import force_distribution as fd
from cdpr_control.model import workspace as ws
from cdpr_control.model.robot import load_robot


@pytest.fixture(scope="module")
def robot():
    return ws.with_platform_mass(load_robot("ipanema3"), 30.0)


@pytest.fixture(scope="module")
def grid_sets(robot):
    grid = ws.workspace_grid(robot, step=0.5)
    return grid, ws.evaluate_workspace(robot, grid.poses, ("cf", "pm", "acf", "ipm", "qp"))


def test_w_cf_within_w_acf_within_w_qp(grid_sets):
    grid, sets = grid_sets
    W_CF, W_ACF, W_QP = sets["cf"], sets["acf"], sets["qp"]
    assert 0 < W_CF.sum() < W_ACF.sum() <= W_QP.sum() < len(W_QP)
    assert np.all(W_ACF[W_CF]) and np.all(W_QP[W_ACF])
    # the thesis finds W_ACF = W_QP; ACF's greedy rank reduction misses a thin rim of the border
    assert (W_QP.sum() - W_ACF.sum()) <= 0.01 * W_QP.sum()
    assert np.array_equal(sets["ipm"], W_ACF) and np.all(sets["pm"][W_CF])


def test_membership_is_the_qp_feasibility_and_agrees_with_daqp(robot, grid_sets):
    grid, sets = grid_sets
    AT, w = ws.static_problem(robot, grid.poses)
    qp = fd.distribute(AT, w, 100.0, 3000.0, method="qp")
    np.testing.assert_array_equal(qp.feasible, sets["qp"])
    # DAQP on a sample concentrated at the border (neighbours of a change of membership)
    border = np.flatnonzero(np.diff(sets["qp"].astype(int)) != 0)
    sample = np.unique(np.r_[border, border + 1, np.arange(0, len(AT), 97)])
    daqp = fd.quadratic_program(AT[sample], w[sample], 100.0, 3000.0, backend="daqp")
    np.testing.assert_array_equal(daqp.feasible, sets["qp"][sample])


def test_wrench_feasible_matches_brute_force_on_random_problems():
    """The Fourier-Motzkin test against the exact kernel QP and DAQP on hand-made robots."""
    from cdpr_test_nodes.force_problems import random_problems

    AT, w = random_problems(300, seed=7)
    member = fd.wrench_feasible(AT, w, 100.0, 3000.0)
    assert 0 < member.sum() < len(member)
    np.testing.assert_array_equal(member, fd.quadratic_program(AT, w, 100.0, 3000.0).feasible)
    np.testing.assert_array_equal(member, fd.quadratic_program(AT, w, 100.0, 3000.0, backend="daqp").feasible)
    assert fd.wrench_feasible(AT[0], w[0], 100.0, 3000.0) == member[0]


def test_infeasible_poses_are_reported_infeasible(robot):
    outside = np.array([[8.1, 5.6, 3.1, 0, 0, 0],        # next to the anchor of cable 1
                        [0.0, 0.0, 0.5, 0.9, 0, 0],      # tilted by 52 deg
                        [0.0, 0.0, 10.0, 0, 0, 0]])      # above the frame
    for method in fd.METHODS:
        assert not ws.feasible_poses(robot, outside, method).any()
    heavy = ws.with_platform_mass(robot, 5000.0)
    assert not ws.feasible_poses(heavy, np.array([robot.home]), "qp").any()
    assert ws.feasible_poses(robot, np.array([robot.home]), "qp").all()


def test_serpentine_order_visits_every_point_with_unit_steps():
    shape = (5, 4, 3)
    order = ws.serpentine_order(shape)
    assert sorted(order) == list(range(60))
    idx = np.array(np.unravel_index(order, shape)).T
    assert np.all(np.abs(np.diff(idx, axis=0)).sum(axis=1) == 1)


def test_grid_covers_the_frame_interior(robot):
    grid = ws.workspace_grid(robot, step=1.0, orientation=(0.0, 0.0, 0.1))
    lo, hi = ws.frame_box(robot)
    pts = grid.points
    assert len(pts) == np.prod(grid.shape)
    assert np.all(pts >= lo - 1e-9) and np.all(pts <= hi + 1e-9)
    assert np.all(grid.poses[:, 5] == 0.1)
    with pytest.raises(ValueError):
        ws.workspace_grid(robot, step=0.0)


def test_hull_vertices_lie_on_the_border(robot, grid_sets):
    hull = ws.workspace_hull(robot, n_directions=150, tol=1e-3)
    assert ws.feasible_poses(robot, np.hstack([hull.vertices, np.zeros((150, 3))])).all()
    d = hull.vertices - hull.center
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    beyond = hull.vertices[hull.bounded] + 3e-3 * d[hull.bounded]
    assert hull.bounded.sum() > 20
    assert not ws.feasible_poses(robot, np.hstack([beyond, np.zeros((len(beyond), 3))])).any()
    grid, sets = grid_sets
    box = np.prod(np.ptp(np.array(ws.frame_box(robot)), axis=0))
    assert 0.2 * box < hull.volume <= box
    # grid cells stick out of the box by half a step, the inscribed triangulation cuts corners
    assert abs(hull.volume - sets["qp"].sum() * grid.step ** 3) < 0.35 * hull.volume


def test_hull_needs_a_feasible_centre(robot):
    with pytest.raises(ValueError, match="not in the workspace"):
        ws.workspace_hull(robot, center=(0.0, 0.0, 10.0))


def test_plot_writes_a_png(robot, grid_sets, tmp_path):
    grid, sets = grid_sets
    hull = ws.workspace_hull(robot, n_directions=60, tol=0.05)
    out = ws.plot_workspace(tmp_path / "wfw.png", grid, {"W_QP": sets["qp"], "W_CF": sets["cf"]}, hull,
                            "test")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_platform_mass_replaces_the_total_mass(robot):
    r = ws.with_platform_mass(robot, 150.0)
    assert r.platform.mass == 150.0 and ws.with_platform_mass(r, None) is r
    with pytest.raises(ValueError):
        ws.with_platform_mass(robot, -1.0)

"""What a 3D view of the robot shows, as plain geometry: frame, pulleys, cables, platform, set-point, wrench.

Everything is in the base frame [m]. The cables run from the pulley leave points C_i (2.8) (the
anchor points a_i without pulleys) to the platform points B_i = r + R b_i (2.1), both from
:func:`cdpr_control.kinematics.inverse_kinematics` of the pose, so the picture is the model's own.
A cable's colour value is its force relative to its limits, (f_i - f_min,i) / (f_max,i - f_min,i)
(0 at f_min, 1 at f_max; outside [0, 1] when a limit (2.39) is violated). The visualization node
turns a :class:`Scene` into ``visualization_msgs/MarkerArray``; no rclpy here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from cdpr_control.kinematics import inverse_kinematics, pulley_frames

PULLEY_SEGMENTS = 24  # straight pieces per pulley circle


@dataclass
class Scene:
    anchors: np.ndarray          # (m, 3) a_i
    frame_edges: np.ndarray      # (k, 2, 3) edges of the frame (bounding box of the a_i)
    pulley_edges: np.ndarray     # (m * PULLEY_SEGMENTS, 2, 3) pulley circles; (0, 2, 3) without pulleys
    cables: np.ndarray           # (m, 2, 3) from C_i to B_i
    force_level: np.ndarray      # (m,) (f - f_min) / (f_max - f_min); NaN where f is unknown
    platform_triangles: np.ndarray  # (t, 3, 3) hull of the B_i
    position: np.ndarray         # (3,) r
    setpoint: np.ndarray | None  # (3,) r_d
    force_arrow: np.ndarray | None  # (2, 3) from r to r + scale * F (force part of w)


def box_edges(lo, hi) -> np.ndarray:
    """The 12 edges (12, 2, 3) of the axis-aligned box [lo, hi]."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    corners = np.array([[(hi if (k >> j) & 1 else lo)[j] for j in range(3)] for k in range(8)])
    return np.array([(corners[k], corners[k | (1 << j)]) for k in range(8) for j in range(3) if not (k >> j) & 1])


def pulley_circles(robot, ik) -> np.ndarray:
    """Edges of each pulley circle in its plane (axes R_A R_z(gamma) e_x and R_A e_z, centre a_i + r_p e_radial)."""
    if not robot.swivelling_pulleys:
        return np.zeros((0, 2, 3))
    R_A = pulley_frames(robot)
    radial = np.cos(ik.gamma)[:, None] * R_A[:, :, 0] + np.sin(ik.gamma)[:, None] * R_A[:, :, 1]
    centre = robot.a + robot.r_p[:, None] * radial
    t = np.linspace(0.0, 2.0 * np.pi, PULLEY_SEGMENTS + 1)
    points = (centre[:, None, :] + robot.r_p[:, None, None]
              * (-np.cos(t)[None, :, None] * radial[:, None, :] + np.sin(t)[None, :, None] * R_A[:, None, :, 2]))
    return np.stack([points[:, :-1], points[:, 1:]], axis=2).reshape(-1, 2, 3)


def platform_triangles(robot, ik, x) -> np.ndarray:
    """Triangles of the convex hull of the platform points B_i (a flat platform: a fan of its outline)."""
    points = ik.Rb + np.asarray(x[:3], float)
    try:
        hull = ConvexHull(robot.b)
        return points[hull.simplices]
    except QhullError:  # coplanar b_i: a fan around their centre, ordered by angle in the plane
        centre = robot.b.mean(axis=0)
        d = robot.b - centre
        _, _, vt = np.linalg.svd(d)
        order = np.argsort(np.arctan2(d @ vt[1], d @ vt[0]))
        c = points.mean(axis=0)
        return np.array([(c, points[i], points[j]) for i, j in zip(order, np.roll(order, -1))])


def default_force_scale(robot) -> float:
    """Arrow length per newton [m/N]: the mean f_max draws a tenth of the frame's diagonal."""
    return 0.1 * float(np.linalg.norm(robot.frame_size)) / float(np.mean(robot.cable.f_max))


def scene(robot, x, f=None, x_d=None, w=None, force_scale: float | None = None) -> Scene:
    """The view of pose ``x`` (6,), with cable forces ``f`` (m,) [N], set-point ``x_d`` (6,) and wrench ``w`` (6,)."""
    x = np.asarray(x, dtype=float)
    ik = inverse_kinematics(robot, x)
    B = ik.Rb + x[:3]
    if f is None:
        level = np.full(robot.m, np.nan)
    else:
        f_min, f_max = robot.cable.f_min, robot.cable.f_max
        level = (np.asarray(f, float) - f_min) / (f_max - f_min)
    arrow = None
    if w is not None:
        scale = default_force_scale(robot) if force_scale is None else force_scale
        arrow = np.array([x[:3], x[:3] + scale * np.asarray(w[:3], float)])
    return Scene(anchors=robot.a.copy(), frame_edges=box_edges(robot.a.min(axis=0), robot.a.max(axis=0)),
                 pulley_edges=pulley_circles(robot, ik), cables=np.stack([ik.c, B], axis=1), force_level=level,
                 platform_triangles=platform_triangles(robot, ik, x), position=x[:3].copy(),
                 setpoint=None if x_d is None else np.asarray(x_d[:3], float), force_arrow=arrow)


def force_colour(level: float) -> tuple[float, float, float]:
    """RGB of a force level: blue at f_min (0), green in the middle, red at f_max (1); magenta outside
    [0, 1] (a violated limit); grey when unknown (NaN)."""
    if not np.isfinite(level):
        return (0.6, 0.6, 0.6)
    if level < 0.0 or level > 1.0:
        return (1.0, 0.0, 1.0)
    if level < 0.5:
        s = level / 0.5
        return (0.0, s, 1.0 - s)
    s = (level - 0.5) / 0.5
    return (s, 1.0 - s, 0.0)

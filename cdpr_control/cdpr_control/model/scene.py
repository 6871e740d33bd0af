"""What a 3D view of the robot shows, as plain geometry: frame, pulleys, cables, platform, set-point, wrench.

Everything is in the base frame [m]. The cables run from the pulley leave points C_i (2.8) (the
anchor points a_i without pulleys) to the platform points B_i = r + R b_i (2.1), both from
:func:`cdpr_control.model.kinematics.inverse_kinematics` of the pose, so the picture is the model's own.
A cable's colour value is its force relative to its limits, (f_i - f_min,i) / (f_max,i - f_min,i)
(0 at f_min, 1 at f_max; outside [0, 1] when a limit (2.39) is violated). The visualization node
turns a :class:`Scene` into ``visualization_msgs/MarkerArray``; no rclpy here.
"""
from __future__ import annotations

from dataclasses import dataclass

import functools

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from cdpr_control.model.kinematics import inverse_kinematics, pulley_frames


@dataclass
class Scene:
    anchors: np.ndarray          # (m, 3) a_i
    frame_edges: np.ndarray      # (k, 2, 3) edges of the frame (bounding box of the a_i)
    pulley_centres: np.ndarray   # (m, 3) centres of the pulley wheels; (0, 3) without pulleys
    pulley_normals: np.ndarray   # (m, 3) unit normals of the pulley planes (the wheels' axles)
    pulley_radii: np.ndarray     # (m,) r_p
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


def pulleys(robot, ik) -> tuple[np.ndarray, np.ndarray]:
    """Centres a_i + r_p R_A R_z(gamma) e_x and plane normals n_i of the pulley wheels (2.8): the
    wheel of radius r_p touches the swivel axis at a_i and the cable leaves it at C_i."""
    if not robot.swivelling_pulleys:
        return np.zeros((0, 3)), np.zeros((0, 3))
    R_A = pulley_frames(robot)
    radial = np.cos(ik.gamma)[:, None] * R_A[:, :, 0] + np.sin(ik.gamma)[:, None] * R_A[:, :, 1]
    return robot.a + robot.r_p[:, None] * radial, ik.n


@functools.lru_cache(maxsize=16)
def _hull_triangles(b_bytes: bytes, m: int) -> np.ndarray:
    """Vertex indices (t, 3) of the hull of the platform points b_i (a fan with index m, the centre, when flat)."""
    b = np.frombuffer(b_bytes).reshape(m, 3)
    try:
        return ConvexHull(b).simplices
    except QhullError:  # coplanar b_i: a fan around their centre, ordered by angle in the plane
        d = b - b.mean(axis=0)
        _, _, vt = np.linalg.svd(d)
        order = np.argsort(np.arctan2(d @ vt[1], d @ vt[0]))
        return np.array([(m, i, j) for i, j in zip(order, np.roll(order, -1))])


def platform_triangles(robot, ik, x) -> np.ndarray:
    """Triangles (t, 3, 3) of the convex hull of the platform points B_i (the hull is computed once per platform)."""
    points = ik.Rb + np.asarray(x[:3], float)
    points = np.vstack([points, points.mean(axis=0)])
    return points[_hull_triangles(np.ascontiguousarray(robot.b, dtype=float).tobytes(), robot.m)]


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
    centres, normals = pulleys(robot, ik)
    return Scene(anchors=robot.a.copy(), frame_edges=box_edges(robot.a.min(axis=0), robot.a.max(axis=0)),
                 pulley_centres=centres, pulley_normals=normals, pulley_radii=robot.r_p[:len(centres)], cables=np.stack([ik.c, B], axis=1), force_level=level,
                 platform_triangles=platform_triangles(robot, ik, x), position=x[:3].copy(),
                 setpoint=None if x_d is None else np.asarray(x_d[:3], float), force_arrow=arrow)


def z_to(n) -> np.ndarray:
    """Unit quaternions (..., 4) as (x, y, z, w) of the shortest rotations taking e_z to the unit vectors ``n`` (..., 3)."""
    n = np.asarray(n, float)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    s, c = np.hypot(n[..., 0], n[..., 1]), n[..., 2]  # |e_z x n| and e_z . n
    half = 0.5 * np.arctan2(s, c)
    safe = np.where(s > 1e-12, s, 1.0)
    q = np.stack([-n[..., 1] / safe * np.sin(half), n[..., 0] / safe * np.sin(half),
                  np.zeros_like(s), np.cos(half)], axis=-1)  # axis e_z x n = (-n_y, n_x, 0)
    antiparallel = (s <= 1e-12) & (c < 0)  # half a turn about x
    q[antiparallel] = (1.0, 0.0, 0.0, 0.0)
    return q


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

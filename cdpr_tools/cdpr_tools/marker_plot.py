"""Markers (``visualization_msgs/MarkerArray``) drawn with matplotlib 3D: what Foxglove's 3D panel shows, as a PNG.

Reads only message fields (``ns``, ``id``, ``type``, ``points``, ``colors``, ``color``, ``scale``,
``pose``), so it draws rclpy messages as well as ones decoded from CDR with their schema
(``mcap_ros2``). Like a viewer, :class:`Scene` keeps the newest marker per (ns, id) across arrays
(the visualization node sends its static markers once a second). The types the visualization node
uses are drawn: LINE_LIST, LINE_STRIP, SPHERE_LIST, SPHERE, CYLINDER (its circle: a pulley disc),
TRIANGLE_LIST, ARROW (from its two points); points are in the header frame (identity poses).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

# visualization_msgs/Marker type constants
ARROW, SPHERE, CYLINDER, LINE_STRIP, LINE_LIST, SPHERE_LIST, TRIANGLE_LIST = 0, 2, 3, 4, 5, 7, 11
CIRCLE_SEGMENTS = 32


class Scene:
    """The newest marker per (ns, id), as a viewer holds them."""

    def __init__(self):
        self.markers: dict[tuple, object] = {}

    def add(self, array) -> "Scene":
        for m in array.markers:
            self.markers[(m.ns, m.id)] = m
        return self

    @property
    def namespaces(self) -> set[str]:
        return {ns for ns, _ in self.markers}


def _rotation(q) -> np.ndarray:
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _xyz(points) -> np.ndarray:
    return np.array([(p.x, p.y, p.z) for p in points], dtype=float).reshape(-1, 3)


def _rgba(c) -> tuple:
    return (c.r, c.g, c.b, c.a)


def plot_markers(markers, path: str | Path, title: str = "", elev: float = 22.0, azim: float = -55.0) -> Path:
    """Render ``markers`` (a :class:`Scene`, a MarkerArray or a list of markers) to ``path`` (PNG)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    fig = plt.figure(figsize=(6.0, 5.0), dpi=100)
    ax = fig.add_subplot(projection="3d")
    if isinstance(markers, Scene):
        markers = list(markers.markers.values())
    elif hasattr(markers, "markers"):
        markers = markers.markers
    everything, labelled = [], set()
    for m in markers:
        label = None if m.ns in labelled else m.ns
        labelled.add(m.ns)
        pts = _xyz(m.points)
        colour = _rgba(m.color)
        if m.type in (LINE_LIST, LINE_STRIP) and len(pts):
            segs = pts.reshape(-1, 2, 3) if m.type == LINE_LIST else np.stack([pts[:-1], pts[1:]], axis=1)
            step = 2 if m.type == LINE_LIST else 1
            colours = [_rgba(c) for c in m.colors[::step]] if len(m.colors) else colour
            width = 2.5 if m.ns == "cables" else 0.8
            ax.add_collection3d(Line3DCollection(segs, colors=colours, linewidths=width, label=label))
        elif m.type == SPHERE_LIST and len(pts):
            ax.scatter(*pts.T, color=colour[:3], s=12, depthshade=False, label=label)
        elif m.type == SPHERE:
            p = m.pose.position
            pts = np.array([[p.x, p.y, p.z]])
            ax.scatter(*pts.T, color=colour[:3], s=40, marker="o", alpha=colour[3], depthshade=False, label=label)
        elif m.type == CYLINDER:  # its rim: a circle of diameter scale.x about the pose's z axis
            p, R = m.pose.position, _rotation(m.pose.orientation)
            t = np.linspace(0.0, 2.0 * np.pi, CIRCLE_SEGMENTS + 1)
            pts = np.array([p.x, p.y, p.z]) + 0.5 * m.scale.x * (np.outer(np.cos(t), R[:, 0]) + np.outer(np.sin(t), R[:, 1]))
            ax.plot(*pts.T, color=colour[:3], linewidth=1.0, label=label)
        elif m.type == TRIANGLE_LIST and len(pts):
            ax.add_collection3d(Poly3DCollection(pts.reshape(-1, 3, 3), facecolors=colour, edgecolors=(0, 0, 0, 0.2),
                                                 linewidths=0.3))
        elif m.type == ARROW and len(pts) == 2:
            d = pts[1] - pts[0]
            ax.quiver(*pts[0], *d, color=colour[:3], linewidth=2, arrow_length_ratio=0.25, label=label)
        everything.append(pts)
    pts = np.vstack([p for p in everything if len(p)])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    ax.set_xlim(lo[0], hi[0]), ax.set_ylim(lo[1], hi[1]), ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(np.maximum(hi - lo, 1e-3))
    ax.set_xlabel("x [m]"), ax.set_ylabel("y [m]"), ax.set_zlabel("z [m]")
    ax.view_init(elev=elev, azim=azim)
    ax.set_title(title or "cables: blue at f_min, green, red at f_max", fontsize=9)
    ax.legend(loc="upper left", fontsize=7, frameon=False)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path

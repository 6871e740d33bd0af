"""The sweep's poses: spread over a robot's wrench-feasible workspace (thesis section 2.2.1).

The workspace is the one the shipped configuration plans with: the weight balanced with cable
forces between the force distribution's f_min (``params/<robot>.yaml``, above the robot file's
limit) and f_max. Its hull (:func:`cdpr_control.model.workspace.workspace_hull`) is seen from home along
rays; a pose at ``s`` times the border distance of its ray is *near the border* when
``s >= 1 - BORDER_BAND`` (within 10 % of the hull's border, measured along the ray). Some poses
are rotated about z where the workspace admits it (the orientation is kept only when the rotated
pose is still wrench-feasible).

The order is deterministic and interleaves border and interior poses, so that the first N poses
(``--poses N``) keep the border share.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdpr_control.control.params import load_params_file
from cdpr_control.model.workspace import feasible_poses, frame_box, workspace_hull

BORDER_BAND = 0.10            # near the border: within 10 % of the border distance along the ray
BORDER_SCALE = (0.91, 0.98)   # border poses: this share of the ray's border distance
INTERIOR_SCALE = (0.2, 0.8)   # interior poses
YAW = np.deg2rad(5.0)         # rotation about z tried at every third pose (ASSUMPTION: small, as both workspaces' orientations are)
N_DIRECTIONS = 200            # rays of the hull


@dataclass(frozen=True)
class SweepPose:
    """One pose of the sweep."""

    index: int
    x: np.ndarray             # (6,) [m, rad]
    scale: float              # share of the border distance along its ray from home
    border: bool              # within BORDER_BAND of the hull's border

    def label(self) -> str:
        p = ", ".join(f"{v:.3f}" for v in self.x[:3])
        rot = f", c {np.rad2deg(self.x[5]):+.0f} deg" if self.x[5] else ""
        return f"#{self.index} [{p}]{rot}{' (border)' if self.border else ''}"


def planned_f_min(robot) -> np.ndarray:
    """f_min the shipped force distribution plans with (the parameter file's, else the robot's)."""
    fd = load_params_file(robot.file.stem).get("force_distribution", {})
    return np.asarray(fd.get("f_min", robot.cable.f_min), dtype=float) * np.ones(robot.m)


def sweep_poses(robot, n: int = 42, seed: int = 0) -> list[SweepPose]:
    """n poses (n >= 3) of the robot's workspace: home, then border and interior poses alternating
    (so that at least a third of every prefix of 3 poses or more is near the border), each on its
    own ray from home that ends at the workspace's border (not at the anchors' box)."""
    if n < 3:
        raise ValueError(f"the grid needs at least 3 poses, got {n}")
    f_min = planned_f_min(robot)
    # searched within the anchors' box: the rays that end inside it end at the workspace's border
    hull = workspace_hull(robot, n_directions=N_DIRECTIONS, f_min=f_min, tol=1e-3 * _size(robot),
                          box=frame_box(robot, 0.0))
    rng = np.random.default_rng(seed)
    rays = rng.permutation(np.flatnonzero(hull.bounded))
    kinds = ["home"] + [("border", "interior")[i % 2] for i in range(n - 1)]
    poses, r = [], 0
    for i, kind in enumerate(kinds):
        while True:
            x = np.array(robot.home, dtype=float)
            if kind == "home":
                s = 0.0
            else:
                lo, hi = BORDER_SCALE if kind == "border" else INTERIOR_SCALE
                s = float(rng.uniform(lo, hi))
                v = hull.vertices[rays[r % len(rays)]]
                r += 1
                x[:3] = hull.center + s * (v - hull.center)
            if i % 3 == 2:
                x[5] = YAW if i % 2 else -YAW
                if not feasible_poses(robot, x[None], f_min=f_min)[0]:
                    x[5] = 0.0
            if feasible_poses(robot, x[None], f_min=f_min)[0]:
                break
        poses.append(SweepPose(i, x, s, s >= 1.0 - BORDER_BAND))
    return poses


def _size(robot) -> float:
    """The frame's largest extent [m] (the hull's tolerance scales with it)."""
    return float(np.ptp(robot.a, axis=0).max())

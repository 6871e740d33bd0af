"""Wrench-feasible workspace (WFW), thesis section 2.2.1, (2.39)-(2.40), Fig. 2.5 and Fig. 2.7.

A pose belongs to the WFW when the platform's static wrench (its weight, constant orientation, no
dynamic forces, as in Fig. 2.5) can be balanced with f_min <= f <= f_max. Each cable force
algorithm sees its own part of it: W_CF (closed form) is smaller than W_ACF, which the thesis
finds equal to the workspace of IPM and QP (Fig. 2.7, section 3.6.2). Here "qp" is the exact
WFW membership test (:func:`cdpr_control.force_distribution.wrench_feasible`); the other methods
count a pose when their distribution is feasible.

* :func:`workspace_grid` / :func:`evaluate_workspace`: batched membership on a grid, per method.
* :func:`workspace_hull`: the hull by the triangulation method of (Pott 2008): rays from a centre
  along the directions of a triangulated sphere, the border found by bisection on every ray at
  once (exact for workspaces star-shaped about the centre).
* :func:`plot_workspace`: a PNG with the hull and a horizontal slice of the grid sets.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from cdpr_control.model.dynamics import gravity_wrench
from cdpr_control.force_distribution import distribute, wrench_feasible
from cdpr_control.model.kinematics import inverse_kinematics

CHUNK = 4096      # poses per batch: big enough to amortise numpy calls, small enough for the cache


def with_platform_mass(robot, mass: float | None):
    """The robot with a total platform mass m_p [kg] (the thesis' "payload m_p", Table 3.3);
    None keeps the robot's own. Centre of gravity and inertia stay as they are."""
    if mass is None:
        return robot
    if not (np.isfinite(mass) and mass > 0.0):
        raise ValueError(f"platform mass must be finite and > 0 kg, got {mass}")
    return replace(robot, platform=replace(robot.platform, mass=float(mass)))


def static_problem(robot, x, pulleys: bool | None = None):
    """(A^T (..., 6, m), w (..., 6)) at poses x (..., 6): structure matrix (2.10) and the weight."""
    return inverse_kinematics(robot, x, pulleys).AT, gravity_wrench(robot, x)


def feasible_poses(robot, x, method: str = "qp", f_min=None, f_max=None, f_ref=None,
                   pulleys: bool | None = None) -> np.ndarray:
    """(N,) bool: poses x (N, 6) in the workspace of a method; limits default to the robot's."""
    return evaluate_workspace(robot, x, (method,), f_min, f_max, f_ref, pulleys)[method]


def evaluate_workspace(robot, x, methods=("cf", "acf", "qp"), f_min=None, f_max=None, f_ref=None,
                       pulleys: bool | None = None) -> dict[str, np.ndarray]:
    """Membership of poses x (N, 6) in W_method for each method, in batches of CHUNK poses.

    Poses where the kinematics has no solution (NaN, e.g. inside a pulley) are outside.
    """
    x = np.asarray(x, dtype=float).reshape(-1, 6)
    f_min = robot.cable.f_min if f_min is None else f_min
    f_max = robot.cable.f_max if f_max is None else f_max
    out = {method: np.empty(len(x), dtype=bool) for method in methods}
    for s in range(0, len(x), CHUNK):
        AT, w = static_problem(robot, x[s:s + CHUNK], pulleys)
        for method in methods:
            if method == "qp":
                member = wrench_feasible(AT, w, f_min, f_max)
            else:
                member = distribute(AT, w, f_min, f_max, f_ref, method).feasible
            out[method][s:s + CHUNK] = member
    return out


@dataclass(frozen=True)
class WorkspaceGrid:
    """Positions on a regular grid at one orientation; points are in C order over (x, y, z)."""

    axes: tuple              # three 1-D arrays of grid coordinates [m]
    orientation: np.ndarray  # (3,) Kardan angles [rad]
    step: float              # grid spacing [m]

    @property
    def shape(self) -> tuple:
        return tuple(len(a) for a in self.axes)

    @property
    def points(self) -> np.ndarray:
        """(N, 3) positions, index order (i_x, i_y, i_z) C-contiguous."""
        g = np.meshgrid(*self.axes, indexing="ij")
        return np.stack([a.ravel() for a in g], axis=1)

    @property
    def poses(self) -> np.ndarray:
        """(N, 6) poses x = [r, orientation]."""
        p = self.points
        return np.hstack([p, np.broadcast_to(self.orientation, p.shape)])


def frame_box(robot, margin: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """The box spanned by the base anchors a_i, shrunk by margin [m]: the robot's whole interior."""
    return robot.a.min(axis=0) + margin, robot.a.max(axis=0) - margin


def workspace_grid(robot, step: float = 0.25, lower=None, upper=None,
                   orientation=(0.0, 0.0, 0.0)) -> WorkspaceGrid:
    """A grid with spacing step [m] over [lower, upper] (default :func:`frame_box`)."""
    if not step > 0.0:
        raise ValueError(f"grid step must be > 0 m, got {step}")
    lo, hi = frame_box(robot)
    lo = lo if lower is None else np.asarray(lower, dtype=float)
    hi = hi if upper is None else np.asarray(upper, dtype=float)
    axes = tuple(np.arange(l, h + 1e-9, step) for l, h in zip(lo, hi))
    return WorkspaceGrid(axes, np.asarray(orientation, dtype=float), float(step))


def serpentine_order(shape) -> np.ndarray:
    """Indices into the flattened grid visiting every point with unit steps between neighbours.

    The path runs along x, turns to the next y row, and layer by layer in z, reversing direction
    each time ("a trajectory which connects all points of the workspace grid underneath each
    other", section 3.6.2).
    """
    nx, ny, nz = shape
    idx = np.arange(nx * ny * nz).reshape(nx, ny, nz)
    order = []
    for k in range(nz):
        layer = idx[:, :, k].T.copy()            # (ny, nx): rows along x
        layer[1::2] = layer[1::2, ::-1]          # boustrophedon within the layer
        if k % 2:
            layer = layer[::-1, ::-1]            # and back through the layer on odd ones
        order.append(layer.ravel())
    return np.concatenate(order)


@dataclass(frozen=True)
class WorkspaceHull:
    """Border of a workspace seen from a centre: vertices on rays, sphere triangulation."""

    center: np.ndarray       # (3,) m
    vertices: np.ndarray     # (k, 3) m, border points
    triangles: np.ndarray    # (t, 3) vertex indices
    bounded: np.ndarray      # (k,) False where the ray reached the search box before the border

    @property
    def volume(self) -> float:
        """Volume [m^3] enclosed by the triangulated hull (sum of tetrahedra from the centre)."""
        v = self.vertices[self.triangles] - self.center
        return float(np.abs(np.einsum("ti,ti->t", v[:, 0], np.cross(v[:, 1], v[:, 2]))).sum() / 6.0)


def workspace_hull(robot, center=None, orientation=(0.0, 0.0, 0.0), method: str = "qp",
                   n_directions: int = 400, tol: float = 1e-3, box=None, f_min=None, f_max=None,
                   pulleys: bool | None = None) -> WorkspaceHull:
    """Hull of W_method by bisection along n_directions rays from center (default robot.home).

    box (lower, upper) bounds the search (default :func:`frame_box`); tol [m] is the accuracy of
    the border on each ray. The centre must be inside the workspace.
    """
    from scipy.spatial import ConvexHull

    c = np.asarray(robot.home[:3] if center is None else center, dtype=float)
    lo, hi = frame_box(robot) if box is None else (np.asarray(box[0]), np.asarray(box[1]))
    d = _sphere_directions(n_directions)
    with np.errstate(divide="ignore"):
        reach = np.minimum(np.where(d > 0, (hi - c) / d, np.inf),
                           np.where(d < 0, (lo - c) / d, np.inf)).min(axis=1)
    inside = lambda rho: feasible_poses(                          # noqa: E731
        robot, np.hstack([c + rho[:, None] * d, np.broadcast_to(orientation, d.shape)]),
        method, f_min, f_max, pulleys=pulleys)
    if not inside(np.zeros(1))[0]:
        raise ValueError(f"the hull centre {c.tolist()} is not in the workspace of {method!r}")
    rho_in, rho_out = np.zeros(len(d)), reach.copy()
    unbounded = inside(rho_out)
    rho_in[unbounded] = rho_out[unbounded]
    while np.any(rho_out - rho_in > tol):
        mid = 0.5 * (rho_in + rho_out)
        ok = inside(mid)
        rho_in = np.where(ok, mid, rho_in)
        rho_out = np.where(ok, rho_out, mid)
    return WorkspaceHull(c, c + rho_in[:, None] * d, ConvexHull(d).simplices, ~unbounded)


def _sphere_directions(n: int) -> np.ndarray:
    """n unit vectors spread evenly over the sphere (Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (1.0 + 5 ** 0.5) * k
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def plot_workspace(path, grid: WorkspaceGrid, sets: dict[str, np.ndarray], hull: WorkspaceHull | None = None,
                   title: str = "") -> Path:
    """PNG: the hull (3-D) and the slice of the grid nearest the hull centre height, per set.

    sets maps a label to an (N,) membership mask over grid.points; later sets are drawn on top of
    earlier ones, so pass them from large to small (e.g. W_QP, W_ACF, W_CF).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(13, 5.5))
    pts = grid.points
    if hull is not None:
        ax = fig.add_subplot(1, 2, 1, projection="3d")
        v = hull.vertices
        ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=hull.triangles, alpha=0.6,
                        color="tab:blue", edgecolor="k", linewidth=0.1)
        ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]",
               title=f"hull, volume {hull.volume:.1f} m$^3$")
        ax.set_box_aspect(np.ptp(v, axis=0))
        z0 = hull.center[2]
    else:
        z0 = float(np.median(grid.axes[2]))
    ax2 = fig.add_subplot(1, 2, 2)
    zk = grid.axes[2][np.argmin(np.abs(grid.axes[2] - z0))]
    on_slice = np.isclose(pts[:, 2], zk)
    for (label, mask), color in zip(sets.items(), ("tab:red", "tab:orange", "tab:blue", "tab:green")):
        sel = on_slice & mask
        ax2.scatter(pts[sel, 0], pts[sel, 1], s=8, marker="s", color=color,
                    label=f"{label}: {mask.sum()} of {len(mask)} poses")
    ax2.set(xlabel="x [m]", ylabel="y [m]", title=f"grid slice z = {zk:.2f} m, step {grid.step} m",
            aspect="equal")
    ax2.legend(loc="upper right", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

"""Stiffness and eigenfrequencies of the platform over the workspace, thesis section 4.3.

At every pose the cables carry the QP forces (3.27) of a tension level holding the platform (with
payload) statically; the cable stiffness is the tangent of the progressive cable (2.16)-(2.17),
(2.20) at those forces, K_x = K_g + K_c (2.22) (:mod:`cdpr_control.model.stiffness`). Reported per pose:

* the per-axis eigenfrequencies (4.8), sqrt(K_x,jj / M_jj) / 2 pi (the thesis' definition, its
  Fig. 4.26 shows the z axis), and the coupled undamped modes of M xddot + K_x x = 0;
* the minimal and maximal eigenvalues of K_x, K_g and K_c (Fig. 4.27-4.28; of the symmetric part,
  K_g is not symmetric away from moment equilibrium);
* the relative shift of the eigenfrequencies from the minimal to the maximal tension level (the
  thesis measures 15-30 % in z, section 4.3).

The thesis' seven measuring points (Table 4.5) are :data:`TABLE_4_5`.

Run: ``cdpr analyze eigenfrequencies [--help]``.
"""
from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdpr_control.model import cable
from cdpr_control.model.dynamics import gravity_wrench, mass_matrix
from cdpr_control.force_distribution import quadratic_program
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot
from cdpr_control.model.stiffness import (cable_stiffness, eigenfrequencies, geometric_stiffness,
    modal_frequencies)
from cdpr_control.model.workspace import workspace_grid
from cdpr_control.analysis.energy import LEVELS
from cdpr_control.analysis.arguments import finite, non_negative, positive

AXES = ("x", "y", "z", "a", "b", "c")
# Table 4.5: positions [m] of the eigenfrequency experiments on the IPAnema 3
TABLE_4_5 = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 1.0], [0.0, 0.0, 1.7], [2.0, 0.0, 0.5],
                      [4.0, 0.0, 0.5], [4.0, 1.5, 0.5], [4.0, 3.0, 0.5]])
THESIS_SHIFT = (0.15, 0.30)          # relative shift of the eigenfrequency by the tension level, 4.3
THESIS_FZ = {25.0: 7.0, 105.0: 3.5}  # Hz, z eigenfrequency at m_p (Fig. 4.26, measured)


@dataclass
class StiffnessMap:
    """Stiffness and eigenfrequencies at poses x (N, 6) for one tension level and payload."""

    x: np.ndarray
    level: float
    payload: float
    feasible: np.ndarray          # (N,) bool, QP forces within f_min .. f_max
    f: np.ndarray                 # (N, m) N
    f_axis: np.ndarray            # (N, 6) Hz, (4.8) per axis
    f_modes: np.ndarray           # (N, 6) Hz, coupled modes ascending (NaN: K_x indefinite)
    eig_K_x: np.ndarray           # (N, 2) N/m, (min, max) eigenvalue (of the symmetric part)
    eig_K_g: np.ndarray           # (N, 2)
    eig_K_c: np.ndarray           # (N, 2)


def _min_max_eig(K) -> np.ndarray:
    lam = np.linalg.eigvalsh(0.5 * (K + np.swapaxes(K, -1, -2)))
    return np.stack([lam[..., 0], lam[..., -1]], axis=-1)


def stiffness_map(robot, x, level: float, payload: float = 0.0) -> StiffnessMap:
    """:class:`StiffnessMap` at poses x (N, 6) with the QP forces of ``level`` [0..1] (3.27)."""
    x = np.atleast_2d(np.asarray(x, dtype=float))
    loaded = robot.with_payload(payload) if payload else robot
    ik = inverse_kinematics(loaded, x)
    c = robot.cable
    result = quadratic_program(ik.AT, gravity_wrench(loaded, x), c.f_min, c.f_max,
                               c.f_min + level * (c.f_max - c.f_min))
    f = np.asarray(result.f)
    k_l = cable.tangent_stiffness(robot, f, cable.total_free_length(robot, ik.q))      # (2.20)
    K_g = geometric_stiffness(ik, f)
    K_c = cable_stiffness(ik, k_l)
    K_x = K_g + K_c                                                                    # (2.22)
    M = mass_matrix(loaded, x)
    with np.errstate(invalid="ignore"):
        f_axis = eigenfrequencies(K_x, M)                                              # (4.8)
    return StiffnessMap(x, level, payload, np.asarray(result.feasible), f, f_axis, modal_frequencies(K_x, M),
                        _min_max_eig(K_x), _min_max_eig(K_g), _min_max_eig(K_c))


def modes(robot, x, f) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies [Hz] (6,), shapes Phi (6, 6)) of M xddot + K_x x = 0 at pose x with forces f.

    Phi is M-orthonormal (Phi^T M Phi = I, columns ascending in frequency), so the modal coordinates
    of a small motion dx = [dr; dtheta] are eta = Phi^T M dx; K_x as in :func:`stiffness_map`.
    """
    from scipy.linalg import eigh

    ik = inverse_kinematics(robot, x)
    k_l = cable.tangent_stiffness(robot, f, cable.total_free_length(robot, ik.q))
    K_x = geometric_stiffness(ik, f) + cable_stiffness(ik, k_l)
    lam, Phi = eigh(0.5 * (K_x + K_x.T), mass_matrix(robot, x))
    with np.errstate(invalid="ignore"):
        return np.sqrt(lam) / (2.0 * np.pi), Phi


def tension_shift(low: StiffnessMap, high: StiffnessMap) -> tuple[np.ndarray, np.ndarray]:
    """Relative shift (N, 6) of the per-axis frequencies (4.8) and of the coupled modes from the
    map ``low`` to ``high`` (same poses and payload); NaN where either is infeasible."""
    ok = (low.feasible & high.feasible)[:, None]
    return (np.where(ok, high.f_axis / low.f_axis - 1.0, np.nan),
            np.where(ok, high.f_modes / low.f_modes - 1.0, np.nan))


@dataclass
class WorkspaceStudy:
    """Maps on a grid for every tension level and payload."""

    robot: str
    grid_shape: tuple
    x: np.ndarray                      # (N, 6)
    maps: dict                         # (level name, payload) -> StiffnessMap


def workspace_study(robot, step: float = 0.25, payloads=(0.0, 80.0), lower=None, upper=None) -> WorkspaceStudy:
    """Stiffness maps over the robot's workspace box (default) at the three tension levels."""
    grid = workspace_grid(robot, step, robot.workspace_min if lower is None else lower,
                          robot.workspace_max if upper is None else upper)
    x = grid.poses
    maps = {(name, p): stiffness_map(robot, x, level, p) for name, level in LEVELS.items() for p in payloads}
    return WorkspaceStudy(robot.name, grid.shape, x, maps)


def shift_statistics(study: WorkspaceStudy, payload: float) -> dict:
    """Percentiles (5, 50, 95) of the minimal -> maximal tension shift over the feasible grid."""
    axis, modes = tension_shift(study.maps[("minimal", payload)], study.maps[("maximal", payload)])
    out = {}
    for j, name in enumerate(AXES[:3]):
        out[f"axis_{name}"] = np.nanpercentile(axis[:, j], (5, 50, 95)).tolist()
    out["first_mode"] = np.nanpercentile(modes[:, 0], (5, 50, 95)).tolist()
    out["poses"] = int(np.isfinite(axis[:, 2]).sum())
    return out


def format_points(robot, points, payload: float) -> str:
    """Table: per point and tension level, f_z (4.8), the coupled modes and eigenvalues (Fig. 4.27)."""
    x = np.hstack([points, np.zeros((len(points), 3))])
    lines = [f"{robot.name}, payload {payload:g} kg (m_p = {robot.platform.mass + payload:g} kg)",
             "point  level    f_z [Hz]  modes [Hz]                              lambda K_x [N/m] min/max   "
             "lambda K_g min/max"]
    for name, level in LEVELS.items():
        s = stiffness_map(robot, x, level, payload)
        for i in range(len(points)):
            if not s.feasible[i]:
                lines.append(f"{i + 1:5d}  {name:7s}  infeasible")
                continue
            lines.append(f"{i + 1:5d}  {name:7s}  {s.f_axis[i, 2]:8.2f}  "
                         + " ".join(f"{v:5.1f}" for v in s.f_modes[i])
                         + f"   {s.eig_K_x[i, 0]:9.3g} {s.eig_K_x[i, 1]:9.3g}   {s.eig_K_g[i, 0]:9.3g} {s.eig_K_g[i, 1]:9.3g}")
    return "\n".join(lines)


def plot_maps(study: WorkspaceStudy, payload: float, z: float, path) -> None:
    """PNG: f_z (4.8) at minimal tension and its shift to maximal tension on the slice nearest z."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shape = study.grid_shape
    X = study.x[:, 0].reshape(shape)
    Y = study.x[:, 1].reshape(shape)
    Z = study.x[:, 2].reshape(shape)
    k = int(np.argmin(np.abs(Z[0, 0, :] - z)))
    low, high = study.maps[("minimal", payload)], study.maps[("maximal", payload)]
    axis, modes = tension_shift(low, high)
    f_z = np.where(low.feasible, low.f_axis[:, 2], np.nan).reshape(shape)[:, :, k]
    panels = ((f_z, "f_z (4.8) at minimal tension [Hz]", "viridis"),
              (100 * axis[:, 2].reshape(shape)[:, :, k], "shift of f_z, minimal -> maximal [%]", "magma"),
              (100 * modes[:, 0].reshape(shape)[:, :, k], "shift of the first coupled mode [%]", "magma"))
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, (values, title, cmap) in zip(axes, panels):
        im = ax.pcolormesh(X[:, :, k], Y[:, :, k], values, shading="nearest", cmap=cmap)
        fig.colorbar(im, ax=ax)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("x [m]")
        ax.set_aspect("equal")
    axes[0].set_ylabel("y [m]")
    fig.suptitle(f"{study.robot}: payload {payload:g} kg, z = {Z[0, 0, k]:.2f} m")
    fig.tight_layout()
    fig.savefig(path, dpi=72)
    plt.close(fig)


def plot_points(robot, points, payload: float, path) -> None:
    """PNG like Fig. 4.27-4.28: min/max eigenvalues of K_x, K_g, K_c per point and tension level."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.hstack([points, np.zeros((len(points), 3))])
    n = np.arange(1, len(points) + 1)
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for ax, key in zip(axes, ("eig_K_x", "eig_K_g", "eig_K_c")):
        for name, level in LEVELS.items():
            lam = getattr(stiffness_map(robot, x, level, payload), key)
            line, = ax.semilogy(n, np.where(lam[:, 1] > 0, lam[:, 1], np.nan), "o-", label=f"max, {name}")
            ax.semilogy(n, np.where(lam[:, 0] > 0, lam[:, 0], np.nan), "s--", color=line.get_color(),
                        label=f"min, {name}")
        ax.set_title(f"eigenvalues of {key[4:]} (negative: not drawn)", fontsize=9)
        ax.set_xlabel("point (Table 4.5)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("lambda [N/m]")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{robot.name}: m_p = {robot.platform.mass + payload:g} kg")
    fig.tight_layout()
    fig.savefig(path, dpi=72)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="cdpr analyze eigenfrequencies",
                                description="Eigenfrequencies (4.8), coupled modes and stiffness eigenvalues over "
                                            "the workspace at minimal, medium and maximal tension (section 4.3).")
    p.add_argument("--robot", default="ipanema3", help="robot name or YAML path")
    p.add_argument("--step", type=positive, default=0.25, help="grid spacing over the robot's workspace box [m]")
    p.add_argument("--payloads", type=non_negative, nargs="+", default=[0.0, 80.0], help="payloads [kg]")
    p.add_argument("--points", type=finite, nargs="+", metavar="XYZ",
                   help="poses x y z ... for the table (default: Table 4.5 for the IPAnema 3, else home)")
    p.add_argument("--z", type=finite, help="height of the map slice [m] (default: home)")
    p.add_argument("--plot-dir", help="write eigenfrequency_maps_<payload>kg.png and stiffness_points.png here")
    p.add_argument("--json", help="write the shift statistics as JSON")
    args = p.parse_args(argv)
    robot = load_robot(args.robot)
    if args.points:
        if len(args.points) % 3:
            p.error("--points takes x y z triples")
        points = np.reshape(args.points, (-1, 3))
    else:
        points = TABLE_4_5 if robot.name == "IPAnema 3" else robot.home[None, :3]
    for payload in args.payloads:
        print(format_points(robot, points, payload))
        print()
    study = workspace_study(robot, args.step, args.payloads)
    stats = {}
    print(f"shift of the eigenfrequencies from minimal to maximal tension over the workspace grid "
          f"(step {args.step} m), percentiles 5/50/95; thesis: {100 * THESIS_SHIFT[0]:.0f}-{100 * THESIS_SHIFT[1]:.0f} %")
    for payload in args.payloads:
        s = shift_statistics(study, payload)
        stats[str(payload)] = s
        print(f"  payload {payload:g} kg ({s['poses']} feasible poses): "
              + ", ".join(f"{k} " + "/".join(f"{100 * v:.1f}" for v in s[k]) + " %"
                          for k in ("axis_x", "axis_y", "axis_z", "first_mode")))
    if args.plot_dir:
        out = Path(args.plot_dir)
        out.mkdir(parents=True, exist_ok=True)
        z = robot.home[2] if args.z is None else args.z
        for payload in args.payloads:
            path = out / f"eigenfrequency_maps_{payload:g}kg.png"
            plot_maps(study, payload, z, path)
            print(f"wrote {path}")
        path = out / "stiffness_points.png"
        plot_points(robot, points, args.payloads[-1], path)
        print(f"wrote {path}")
    if args.json:
        Path(args.json).write_text(json.dumps(stats, indent=2))
    return 0

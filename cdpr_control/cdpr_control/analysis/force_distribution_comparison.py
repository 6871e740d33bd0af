"""Comparison of the cable force algorithms, thesis section 3.6.2, Tables 3.2 and 3.3.

Table 3.2: every method along a trajectory through all points of the IPAnema 3 workspace grid
(:func:`cdpr_control.model.workspace.serpentine_order`), per workspace set W_CF, W_ACF and
W_ACF \\ W_CF: the mean cable force and the change rates xi_M and xi_RMS of the distribution.
Table 3.3: mean cable forces over W_ACF for several platform masses m_p, QP with f_ref = f_min
and f_ref = f_max relative to ACF.

The thesis states neither the grid nor the speed along the trajectory; both are parameters here
(default 0.25 m and 1 m/s, so consecutive grid points are 250 ms apart). The change rate of the
distribution between consecutive poses k, k+1 that both lie in the set is
xi_dot = (f_{k+1} - f_k) / dt [N/ms], and

    xi_M   = E |xi_dot_i|                (mean over steps and cables)
    xi_RMS = sqrt(E xi_dot^T xi_dot) / m (RMS of the force vector's rate, averaged over m cables)

(the thesis' xi_RMS < xi_M in Table 3.2 rules out a per-cable RMS, which is never below the mean
absolute value; xi_RMS_cable = sqrt(E xi_dot^T xi_dot / m) is reported as well). Absolute change
rates scale with speed / step; compare the methods' ratios with the thesis.

Run: python -m cdpr_control.analysis.force_distribution_comparison [--help]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass

import numpy as np

from cdpr_control.force_distribution import distribute
from cdpr_control.model.robot import load_robot
from cdpr_control.model.workspace import (WorkspaceGrid, plot_workspace, serpentine_order, static_problem,
    with_platform_mass, workspace_grid, workspace_hull)
from cdpr_control.analysis.arguments import positive

# Table 3.2 of the thesis: (method, set) -> (mean force [N], xi_M [N/ms], xi_RMS [N/ms]).
THESIS_TABLE_3_2 = {
    ("ACF/CF", "W_CF"): (1314.4, 0.739, 0.537),
    ("IPM/PM/CFE", "W_CF"): (358.0, 0.784, 0.299),
    ("QP_min", "W_CF"): (320.4, 0.477, 0.211),
    ("QP_med", "W_CF"): (1314.4, 0.739, 0.537),
    ("QP_max", "W_CF"): (1977.6, 1.355, 0.824),
    ("ACF", "W_ACF"): (1279.3, 0.997, 0.588),
    ("IPM", "W_ACF"): (434.5, 1.160, 0.396),
    ("QP_min", "W_ACF"): (378.8, 0.996, 0.342),
    ("QP_med", "W_ACF"): (1279.3, 0.998, 0.589),
    ("QP_max", "W_ACF"): (1900.8, 1.308, 0.794),
    ("ACF", "W_ACF\\W_CF"): (1017.8, 2.597, 1.107),
    ("IPM", "W_ACF\\W_CF"): (1005.0, 2.944, 1.185),
    ("QP_min", "W_ACF\\W_CF"): (813.7, 2.802, 1.330),
    ("QP_med", "W_ACF\\W_CF"): (1017.9, 2.600, 1.109),
    ("QP_max", "W_ACF\\W_CF"): (1329.1, 2.456, 0.779),
}
# Table 3.3: m_p [kg] -> (QP f_ref = f_min [N], ACF [N], QP f_ref = f_max [N]).
THESIS_TABLE_3_3 = {30: (487.8, 1112.1, 1536.8), 50: (519.6, 1125.0, 1555.0),
                    100: (661.1, 1161.0, 1564.9), 150: (754.3, 1200.1, 1574.6)}
THESIS_CF_WORKSPACE_SHARE = 0.575      # |W_CF| / |W_ACF|, section 3.6.2


@dataclass(frozen=True)
class Row32:
    """One line of Table 3.2."""

    method: str
    workspace: str
    poses: int
    mean_force: float        # N
    xi_M: float              # N/ms
    xi_RMS: float            # N/ms
    xi_RMS_cable: float      # N/ms


@dataclass(frozen=True)
class Row33:
    """One line of Table 3.3."""

    mass: float              # kg, total platform mass m_p
    poses: int               # |W_ACF| on the grid
    qp_min: float            # N
    acf: float               # N
    qp_max: float            # N

    @property
    def delta_min(self) -> float:
        return 100.0 * (self.qp_min / self.acf - 1.0)

    @property
    def delta_max(self) -> float:
        return 100.0 * (self.qp_max / self.acf - 1.0)


@dataclass(frozen=True)
class Comparison:
    """Everything the comparison computes; see :func:`compare_force_distributions`."""

    robot: str
    mass: float
    step: float
    speed: float
    grid_poses: int
    W_QP: int
    W_ACF: int
    W_CF: int
    table_3_2: list
    table_3_3: list
    seconds: float

    @property
    def cf_share(self) -> float:
        """|W_CF| / |W_ACF| (thesis: 57.5 %)."""
        return self.W_CF / self.W_ACF


def grid_problem(robot, grid: WorkspaceGrid, pulleys=None, chunk=8192):
    """A^T and w at all grid poses, in the order of the serpentine trajectory."""
    poses = grid.poses[serpentine_order(grid.shape)]
    parts = [static_problem(robot, poses[s:s + chunk], pulleys) for s in range(0, len(poses), chunk)]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def run_methods(AT, w, f_min, f_max) -> dict:
    """Results of CF, PM, CFE, ACF, IPM (medium f_ref) and QP at f_ref = f_min / medium / f_max."""
    f_med = (np.asarray(f_min) + np.asarray(f_max)) / 2.0
    out = {name: distribute(AT, w, f_min, f_max, None, name) for name in ("cf", "pm", "cfe", "acf", "ipm")}
    for label, f_ref in (("QP_min", f_min), ("QP_med", f_med), ("QP_max", f_max)):
        out[label] = distribute(AT, w, f_min, f_max, f_ref, "qp")
    return out


def change_rate_stats(f, member, dt) -> tuple[float, float, float, float]:
    """(mean force, xi_M, xi_RMS, xi_RMS_cable) of forces f (N, m) along the trajectory, over
    the poses in member (N,) and the steps whose both ends are in it; dt [s] per step."""
    steps = member[:-1] & member[1:]
    if not member.any():
        return (np.nan,) * 4
    mean = float(f[member].mean())
    if not steps.any():
        return mean, np.nan, np.nan, np.nan
    xi = (f[1:] - f[:-1])[steps] / (dt * 1e3)                       # N/ms
    m = f.shape[1]
    sq = float((xi * xi).sum(axis=1).mean())
    return mean, float(np.abs(xi).mean()), float(np.sqrt(sq) / m), float(np.sqrt(sq / m))


def table_3_2(results: dict, dt: float) -> list[Row32]:
    """Rows of Table 3.2 from :func:`run_methods`' results on the trajectory."""
    W_CF = results["cf"].feasible
    W_ACF = results["acf"].feasible
    sets = {"W_CF": W_CF, "W_ACF": W_ACF, "W_ACF\\W_CF": W_ACF & ~W_CF}
    plan = [("ACF/CF", "cf", "W_CF"), ("IPM/PM/CFE", "pm", "W_CF")]
    plan += [(q, q, "W_CF") for q in ("QP_min", "QP_med", "QP_max")]
    for s in ("W_ACF", "W_ACF\\W_CF"):
        plan += [("ACF", "acf", s), ("IPM", "ipm", s)] + [(q, q, s) for q in ("QP_min", "QP_med", "QP_max")]
    rows = []
    for label, key, s in plan:
        member = sets[s] & results[key].feasible
        rows.append(Row32(label, s, int(member.sum()), *change_rate_stats(results[key].f, member, dt)))
    return rows


def table_3_3(robot, masses, step: float, pulleys=None, done=lambda k: None) -> list[Row33]:
    """Rows of Table 3.3: mean forces over W_ACF per total platform mass m_p [kg]; ``done(k)`` after row k."""
    rows = []
    for k, mass in enumerate(masses):
        r = with_platform_mass(robot, mass)
        grid = workspace_grid(r, step)
        AT, w = grid_problem(r, grid, pulleys)
        f_min, f_max = r.cable.f_min, r.cable.f_max
        acf = distribute(AT, w, f_min, f_max, None, "acf")
        W = acf.feasible
        qp_min = distribute(AT[W], w[W], f_min, f_max, f_min, "qp")
        qp_max = distribute(AT[W], w[W], f_min, f_max, f_max, "qp")
        rows.append(Row33(float(mass), int(W.sum()), float(qp_min.f.mean()), float(acf.f[W].mean()),
                          float(qp_max.f.mean())))
        done(k)
    return rows


def compare_force_distributions(robot: str = "ipanema3", mass: float = 30.0, step: float = 0.25,
                                speed: float = 1.0, masses=(30.0, 50.0, 100.0, 150.0),
                                pulleys: bool | None = None, progress=None) -> Comparison:
    """Tables 3.2 (at platform mass m_p = mass [kg]) and 3.3 (for each of masses) on a grid with
    spacing step [m] over the robot's frame, trajectory speed [m/s]; see the module docstring.
    ``progress(fraction, what)``, if given, is told how far the work is (Table 3.2 is half of it)."""
    progress = progress or (lambda fraction, what: None)
    t0 = time.perf_counter()
    base = load_robot(robot)
    r = with_platform_mass(base, mass)
    grid = workspace_grid(r, step)
    AT, w = grid_problem(r, grid, pulleys)
    progress(0.1, "Table 3.2: grid")
    results = run_methods(AT, w, r.cable.f_min, r.cable.f_max)
    rows = table_3_2(results, step / speed)
    progress(0.5, "Table 3.3")
    table_33 = table_3_3(base, masses, step, pulleys,
                         lambda k: progress(0.5 + 0.5 * (k + 1) / len(masses), f"Table 3.3: m_p = {masses[k]:g} kg"))
    return Comparison(robot, float(mass), float(step), float(speed), len(AT),
                      int(results["QP_med"].feasible.sum()), int(results["acf"].feasible.sum()),
                      int(results["cf"].feasible.sum()), rows, table_33,
                      time.perf_counter() - t0)


def format_report(c: Comparison) -> str:
    """The two tables as text, with the thesis' values alongside."""
    share = f"{100 * c.cf_share:.1f} % of W_ACF (thesis {100 * THESIS_CF_WORKSPACE_SHARE:.1f} %)"
    lines = [
        f"Cable force algorithms on the {c.robot} workspace grid: step {c.step} m, "
        f"{c.grid_poses} poses, m_p = {c.mass} kg, trajectory speed {c.speed} m/s ({c.seconds:.1f} s)",
        f"|W_QP| = {c.W_QP}, |W_ACF| = {c.W_ACF}, |W_CF| = {c.W_CF}: W_CF is {share}, "
        f"W_ACF is {100 * c.W_ACF / c.W_QP:.2f} % of W_QP",
        "",
        "Table 3.2            ours                                          | thesis",
        f"{'method':<11} {'set':<11} {'poses':>6} {'mean f [N]':>10} {'xi_M':>7} {'xi_RMS':>7} "
        f"{'xi_RMS_c':>8} | {'mean f':>7} {'xi_M':>6} {'xi_RMS':>6}   [N/ms]",
    ]
    for row in c.table_3_2:
        ref = THESIS_TABLE_3_2.get((row.method, row.workspace), (np.nan,) * 3)
        lines.append(f"{row.method:<11} {row.workspace:<11} {row.poses:>6} {row.mean_force:>10.1f} "
                     f"{row.xi_M:>7.3f} {row.xi_RMS:>7.3f} {row.xi_RMS_cable:>8.3f} "
                     f"| {ref[0]:>7.1f} {ref[1]:>6.3f} {ref[2]:>6.3f}")
    lines += ["", "Table 3.3: mean cable forces over W_ACF        ours                          | thesis",
              f"{'m_p [kg]':>8} {'poses':>6} {'QP f_min':>9} {'d [%]':>6} {'ACF':>8} {'QP f_max':>9} "
              f"{'d [%]':>6} | {'QP f_min':>8} {'ACF':>7} {'QP f_max':>8}"]
    for row in c.table_3_3:
        ref = THESIS_TABLE_3_3.get(int(round(row.mass)), (np.nan,) * 3)
        lines.append(f"{row.mass:>8.0f} {row.poses:>6} {row.qp_min:>9.1f} {row.delta_min:>6.1f} "
                     f"{row.acf:>8.1f} {row.qp_max:>9.1f} {row.delta_max:>6.1f} "
                     f"| {ref[0]:>8.1f} {ref[1]:>7.1f} {ref[2]:>8.1f}")
    return "\n".join(lines)


def main(argv=None, progress=None) -> int:
    parser = argparse.ArgumentParser(
        prog="cdpr analyze force-distribution",
        description="Tables 3.2 and 3.3 of the thesis: cable force algorithms over the workspace grid.")
    parser.add_argument("--robot", default="ipanema3", help="robot name or YAML path")
    parser.add_argument("--mass", type=positive, default=30.0, help="platform mass m_p for Table 3.2 [kg]")
    parser.add_argument("--step", type=positive, default=0.25, help="grid spacing [m]")
    parser.add_argument("--speed", type=positive, default=1.0, help="speed along the trajectory [m/s]")
    parser.add_argument("--masses", type=positive, nargs="*", default=[30.0, 50.0, 100.0, 150.0],
                        help="platform masses m_p for Table 3.3 [kg]")
    parser.add_argument("--no-pulleys", action="store_true", help="kinematics without swivelling pulleys")
    parser.add_argument("--json", help="also write the numbers to this JSON file")
    parser.add_argument("--plot", help="also write a PNG of the workspace sets and hull (m_p = --mass)")
    args = parser.parse_args(argv)
    pulleys = False if args.no_pulleys else None
    c = compare_force_distributions(args.robot, args.mass, args.step, args.speed, args.masses, pulleys, progress)
    print(format_report(c))
    if args.json:
        data = asdict(c)
        data["table_3_3"] = [{**asdict(r), "delta_min_percent": r.delta_min,
                              "delta_max_percent": r.delta_max} for r in c.table_3_3]
        with open(args.json, "w") as fh:
            json.dump(data, fh, indent=2)
    if args.plot:
        png = plot_comparison_workspace(args.robot, args.mass, args.step, args.plot, pulleys)
        print(f"workspace plot: {png}")
    return 0


def plot_comparison_workspace(robot: str, mass: float, step: float, path, pulleys=None):
    """PNG of W_QP, W_ACF, W_CF on the grid and the hull of W_QP (Fig. 2.5/2.7 analogue)."""
    from cdpr_control.model.workspace import evaluate_workspace

    r = with_platform_mass(load_robot(robot), mass)
    grid = workspace_grid(r, step)
    sets = evaluate_workspace(r, grid.poses, ("qp", "acf", "cf"), pulleys=pulleys)
    hull = workspace_hull(r, pulleys=pulleys)
    return plot_workspace(path, grid, {"W_QP": sets["qp"], "W_ACF": sets["acf"], "W_CF": sets["cf"]}, hull,
                          f"{r.name}: wrench-feasible workspace, m_p = {mass} kg, "
                          f"f in [{r.cable.f_min.min():.0f}, {r.cable.f_max.max():.0f}] N")


if __name__ == "__main__":
    sys.exit(main())

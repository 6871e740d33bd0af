"""Accuracy of the controller against the simulated robot, the mismatched plant beside the
perfect model (cdpr_sim.plant), for the figures the thesis reports on its robots:

* static accuracy, section 4.2.2: the IPAnema 3 holds the points of table 4.3 that lie in the
  robot file's workspace box, with IK only and with force control at minimal and medium tension;
  absolute position and orientation error against the ground truth ("laser tracker");
* the Mini's cuboid program, section 4.2.4: path error and cable forces in the single-process loop;
* identification accuracy from simulated bags (section 3.7.2, 3.3.1, 4.1): the fits against the
  plant's parameters and against the robot file's.

Writes bench/accuracy.json. Run: .venv/bin/python benchmarks/bench_accuracy.py [static] [cuboid] [identification] [--quick]
"""
from __future__ import annotations

import json
import pathlib
import sys
import tempfile

import numpy as np

from cdpr_control import programs
from cdpr_control.control.params import control_loop_params
from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.interpolation import Interpolator
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import program, run
from cdpr_sim.simulator import SimConfig, plant_of
from cdpr_sim.startup import startup_forces
from cdpr_tools.bag import BagReader
from cdpr_tools.identify import drive, experiments, friction, mass

OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "accuracy.json"
PLANTS = ("mismatched", "nominal")
MOVE, HOLD = 4.0, 10.0      # s: cosine move from home, then held (the OSPC's integral time is about 2.6 s)
# table 4.3 (x, y, z) [m]; the ones outside the robot file's workspace box are skipped
TABLE_4_3 = [(x, y, z) for x in (-1.0, -3.0, -5.0) for (y, z) in ((0.0, 2.0), (-3.0, 1.5), (-4.0, 0.0),
                                                                    (-2.0, 0.0), (0.0, 0.0))]


def _move(x_a, x_b, T):
    def source(t):
        u = min(t / T, 1.0)
        s = 0.5 * (1.0 - np.cos(np.pi * u))
        v = 0.5 * np.pi / T * np.sin(np.pi * u) if u < 1.0 else 0.0
        return x_a + s * (x_b - x_a), v * (x_b - x_a), np.zeros(6)
    return source


def static_accuracy(quick: bool) -> dict:
    robot = load_robot("ipanema3")
    lo, hi = robot.workspace_min, robot.workspace_max
    points = [p for p in TABLE_4_3 if np.all(np.asarray(p) >= lo) and np.all(np.asarray(p) <= hi)]
    points = [p for p in points if _feasible(robot, p)][: 2 if quick else None]
    configs = {"ik_only": ("ik_only", 0.0), "force_control_minimal": ("force_control", 0.0),
               "force_control_medium": ("force_control", 0.5)}
    result = {"points": [list(p) for p in points]}
    for plant in PLANTS:
        for name, (mode, level) in configs.items():
            params = control_loop_params(robot, mode=mode)
            params.force.tension_level = level
            pos, ori = [], []
            for p in points:
                x_d = np.r_[p, robot.home[3:]]
                r = run(robot, _move(robot.home, x_d, MOVE), MOVE + HOLD, params, tension_level=level,
                        config=SimConfig(plant=plant))
                pos.append(1e3 * float(np.linalg.norm(r.x[-1, :3] - x_d[:3])))
                ori.append(float(np.rad2deg(np.abs(r.x[-1, 3:] - x_d[3:])).max()))
            result[f"{plant}/{name}"] = {"pos_err_mean_mm": float(np.mean(pos)), "pos_err_std_mm": float(np.std(pos)),
                                         "pos_err_max_mm": float(np.max(pos)), "ori_err_mean_deg": float(np.mean(ori)),
                                         "ori_err_max_deg": float(np.max(ori))}
            print(plant, name, result[f"{plant}/{name}"], flush=True)
    return result


def _feasible(robot, p) -> bool:
    try:
        startup_forces(robot, np.r_[p, 0.0, 0.0, 0.0], 0.0)
        return True
    except ValueError:
        return False


def cuboid() -> dict:
    robot = load_robot("ipanema3_mini")
    result = {}
    for plant in PLANTS:
        for mode in ("force_control", "ik_only"):
            interp = Interpolator(parse_gcode(programs.read("cuboid_mini"), start_pose=robot.home), dt=1e-3)
            r = run(robot, program(interp), interp.duration + 0.2, control_loop_params(robot, mode=mode),
                    config=SimConfig(plant=plant))
            err = 1e3 * np.linalg.norm(r.x[:, :3] - r.x_d[:, :3], axis=1)
            result[f"{plant}/{mode}"] = {"path_err_rms_mm": float(np.sqrt(np.mean(err**2))),
                                         "path_err_max_mm": float(err.max()), "end_err_mm": float(err[-1]),
                                         "f_min_N": float(r.f.min()), "f_max_N": float(r.f.max())}
            print("cuboid", plant, mode, result[f"{plant}/{mode}"], flush=True)
    return result


def identification(tmp: pathlib.Path) -> dict:
    """Fits on the default (mismatched) plant's bags: relative error against the plant and the file."""
    name = "ipanema3_mini"
    robot = load_robot(name)
    true = plant_of(robot, SimConfig()).robot
    rel = lambda a, b: float(np.max(np.abs(np.asarray(a) / np.asarray(b) - 1.0)))  # noqa: E731
    out = {}
    bag = experiments.record_friction_run(tmp / "friction", name, seed=3, amplitudes=(0.0005, 0.002, 0.005),
                                          pause=0.05, fast_amplitude=0.01, fast_velocities=(0.2, 0.4))
    _, fits = friction.identify(BagReader(bag), robot)
    for key in ("mu", "F_pv", "sigma"):
        fit = np.array([getattr(f, key) for f in fits])
        out[f"friction_{key}_max_rel_err_vs_plant"] = rel(fit, getattr(true.friction, key))
        out[f"friction_{key}_max_rel_err_vs_file"] = rel(fit, getattr(robot.friction, key))
    for rname, kind in (("ipanema3", "pt1_deadtime"), ("ipanema3_mini", "second_order")):
        bag = experiments.record_drive_sweep(tmp / f"sweep_{rname}", rname, cable=2, duration=1.5, f_end=60.0, seed=2)
        _, fit = drive.identify(BagReader(bag), kind)
        d_true, d_file = plant_of(load_robot(rname), SimConfig()).robot.drive, load_robot(rname).drive
        for key in (("T_1", "T_d") if kind == "pt1_deadtime" else ("T_w", "zeta", "T_d")):
            out[f"drive_{rname}_{key}_fit"] = float(fit.params[key])
            out[f"drive_{rname}_{key}_plant"] = float(getattr(d_true, key))
            out[f"drive_{rname}_{key}_file"] = float(getattr(d_file, key))
    bag = experiments.record_circle_run(tmp / "circle", name, seed=4, r_c=0.1, frequency=1.0, revolutions=2, ramp=0.6)
    m = mass.identify(BagReader(bag), robot)
    out["mass_circle_rel_err"] = float(m.m_circle / true.platform.mass - 1.0)
    out["mass_static_rel_err"] = float(m.m_static / true.platform.mass - 1.0)
    print("identification", out, flush=True)
    return out


def main(argv) -> None:
    """Parts named on the command line (static, cuboid, identification; default all) are measured
    and replace their entries in bench/accuracy.json; --quick takes two static points."""
    quick = "--quick" in argv
    parts = [a for a in argv if not a.startswith("--")] or ["static", "cuboid", "identification"]
    result = json.loads(OUT.read_text()) if OUT.exists() else {}
    result["plants"] = {n: plant_of(load_robot(n), SimConfig()).summary() for n in ("ipanema3", "ipanema3_mini")}
    with tempfile.TemporaryDirectory() as tmp:
        if "static" in parts:
            result["static_accuracy_ipanema3"] = static_accuracy(quick)
        if "cuboid" in parts:
            result["cuboid_mini"] = cuboid()
        if "identification" in parts:
            result["identification"] = identification(pathlib.Path(tmp))
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=1, default=float))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main(sys.argv[1:])

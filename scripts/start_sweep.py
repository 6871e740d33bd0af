"""The start-up at every pose of the validation grid: each pose held for DURATION seconds on its plant
(the sweep's round robin of the default mismatched plant's seeds and the nominal one) under the shipped
force control and under the IK-only reference; prints per run the highest force above f_max, the
lowest below f_min and whether the safety layer held, then the count of held runs (docs/control.md,
"A start ramp").

    .venv/bin/python scripts/start_sweep.py ipanema3_mini [--poses 40] [--duration 1.0]
"""
from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from cdpr_control.control.params import control_loop_params
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import hold, run
from cdpr_tools.validate.cases import CaseSpec, sim_config
from cdpr_tools.validate.grid import sweep_poses
from cdpr_tools.validate.sweep import plants


def start_run(robot, pose, plant: str, seed: int, mode: str, duration: float) -> str:
    params = dataclasses.replace(control_loop_params(robot), mode=mode)
    config = sim_config(CaseSpec("start", robot.file.stem, pose.index, list(pose.x), pose.border, plant, seed))
    r = run(robot, hold(pose.x), duration, params=params, x0=pose.x, config=config)
    held = next((f"held at {r.t[k]:.3f} s: {f.message}" for k, faults in enumerate(r.faults) for f in faults
                 if f.holds), "")
    c = robot.cable
    return f"peak {r.f.max() - c.f_max.max():+.1f} N, low {r.f.min() - c.f_min.min():+.1f} N {held}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robot")
    parser.add_argument("--poses", type=int, default=40)
    parser.add_argument("--duration", type=float, default=1.0)
    args = parser.parse_args()
    robot = load_robot(args.robot)
    plant_list = plants()
    held = total = 0
    for pose in sweep_poses(robot, args.poses):
        plant, seed = plant_list[pose.index % len(plant_list)]
        for mode in ("force_control", "ik_only"):
            line = start_run(robot, pose, plant, seed, mode, args.duration)
            held += "held at" in line
            total += 1
            print(f"{pose.label()} {plant} {seed} {mode}: {line}", flush=True)
    print(f"held: {held} of {total}")


if __name__ == "__main__":
    main()

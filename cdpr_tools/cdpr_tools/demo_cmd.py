"""``cdpr demo``: the project's main job.

Target (issue 7): the IPAnema 3 Mini in the simulator runs a shipped G-code program through the
whole node graph with OSPC + CFC and the QP at minimal tension, records a bag under bags/ and prints
pose error, cable forces against limits, real-time factor and the bag path.

Until every part exists, the demo runs the stages that are ready, in order, and names the ones
that are missing; it never fakes a result.
"""
from __future__ import annotations

import importlib.util

import numpy as np

from cdpr_control.robot import load_robot

# (stage, module that must exist, issue that delivers it)
STAGES = (
    ("robot description", "cdpr_control.robot", 2),
    ("G-code program and jerk-limited interpolation", "cdpr_control.interpolation", 6),
    ("inverse kinematics along the program", "cdpr_control.kinematics", 3),
    ("cable force distribution along the program", "cdpr_control.force_distribution", 4),
    ("pybullet winch and platform simulator", "cdpr_sim.simulator", 5),
    ("closed loop through the node graph, bag recording", "cdpr_tools.launch", 7),
)


def add_parser(sub) -> None:
    p = sub.add_parser("demo", help="run the main job (simulated robot, G-code program, bag)")
    p.add_argument("--robot", default="ipanema3_mini", help="robot name or YAML path")
    p.set_defaults(run=run)


def run(args) -> int:
    robot = load_robot(args.robot)
    np.set_printoptions(precision=4, suppress=True)
    print(f"[demo] robot: {robot.name}, {robot.m} cables, platform {robot.platform.mass} kg, "
          f"f in [{robot.cable.f_min.min()}, {robot.cable.f_max.max()}] N")
    missing = [(name, issue) for name, module, issue in STAGES if not _exists(module)]
    ready = [name for name, module, _ in STAGES if _exists(module)]
    print("[demo] stages ready: " + "; ".join(ready))
    if missing:
        print("[demo] not yet available, so the main job cannot run end to end:")
        for name, issue in missing:
            print(f"         - {name} (issue {issue})")
        return 0
    return 0


def _exists(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False

"""``cdpr robot``: list the shipped robots or show one robot's validated description."""
from __future__ import annotations

import numpy as np

from cdpr_control.model.robot import available_robots, load_robot


def add_parser(sub) -> None:
    p = sub.add_parser("robot", help="list shipped robots or show one (validates the file)")
    p.add_argument("robot", nargs="?", help="robot name (e.g. ipanema3_mini) or path to a YAML file")
    p.set_defaults(run=run)


def run(args) -> int:
    if not args.robot:
        for name in available_robots():
            print(name)
        return 0
    robot = load_robot(args.robot)
    np.set_printoptions(precision=4, suppress=True)
    print(f"{robot.name} ({robot.file})")
    print(f"  cables m = {robot.m}, DOF n = {robot.n}, swivelling pulleys: {robot.swivelling_pulleys}")
    print(f"  f_min = {robot.cable.f_min} N, f_max = {robot.cable.f_max} N")
    print(f"  platform mass = {robot.platform.mass} kg, centre of gravity = {robot.platform.center_of_gravity} m")
    print(f"  drive model = {robot.drive.model}, v_max = {robot.drive.v_max} m/s")
    return 0

"""The shipped cylinder_contact_force.gcode on the IPAnema 3 in the in-process closed loop
(nominal plant = robot file) against a barrel around the programmed path, with M103/M104 as the
program says: prints the state sequence, the contact force error along the surface normal while
moving in state D, and the cable force range (docs/hybrid_force_control.md, "Following").

    python scripts/cylinder_contact_run.py [stiffness N/m] [friction]     (about 50 s simulated)
"""
import itertools
import sys

import numpy as np

from cdpr_control import programs
from cdpr_control.control_loop import ControlLoopParams
from cdpr_control.force_setpoint import ForceSetpointParams
from cdpr_control.gcode import parse_gcode
from cdpr_control.hybrid_force_control import HPFCParams
from cdpr_control.interpolation import Interpolator
from cdpr_control.robot import load_robot
from cdpr_sim.closed_loop import program, run
from cdpr_sim.contacts import ContactMaterial, Cylinder, PlatformShape
from cdpr_sim.simulator import SimConfig

TOOL = 0.02          # m, tool sphere at the platform origin: the origin moves on the 200 mm circle


def main(stiffness: float = 1e6, friction: float = 0.3) -> None:
    robot = load_robot("ipanema3")
    interp = Interpolator(parse_gcode(programs.read("cylinder_contact_force"), start_pose=robot.home), dt=1e-3)
    barrel = Cylinder((0.0, 0.0, -0.28), (1.0, 0.0, 0.0), 0.2 - TOOL, 0.9,
                      ContactMaterial(stiffness, 0.01 * stiffness, friction))
    config = SimConfig(obstacles=(barrel,), platform_shape=PlatformShape("sphere", TOOL, (0.0, 0.0, 0.0)))
    params = ControlLoopParams(force=ForceSetpointParams(f_min=np.full(robot.m, 150.0)), hpfc=HPFCParams())
    r = run(robot, program(interp), interp.duration + 0.5, params, config=config)
    states = np.array([s.state for s in r.hpfc])
    print("states:", " ".join(f"{s}({len(list(g))} ms)" for s, g in itertools.groupby(states)))
    rel = r.x[:, 1:3] - [0.0, -0.28]
    normal = np.c_[np.zeros(len(rel)), rel / np.linalg.norm(rel, axis=1)[:, None]]
    F_n = np.sum(r.w_contact[:, :3] * normal, axis=1)            # the barrel pushes along the normal
    F_d = np.array([s.F_d for s in r.hpfc])
    speed = np.r_[0.0, np.linalg.norm(np.diff(r.x_d[:, :3], axis=0), axis=1) / 1e-3]
    moving = (speed > 0.005) & (states == "D") & (F_d > 49.0)
    error = np.abs(F_n[moving] - F_d[moving])
    print(f"moving in contact {moving.sum() * 1e-3:.1f} s: |F - F_d| max {error.max():.1f} N, "
          f"rms {np.sqrt(np.mean(error ** 2)):.1f} N, 99th percentile {np.percentile(error, 99):.1f} N")
    print(f"cable forces {r.f.min():.1f} .. {r.f.max():.1f} N (limits {robot.cable.f_min.min():.0f} .. "
          f"{robot.cable.f_max.max():.0f} N); end pose {np.round(r.x[-1, :3], 4)} for {np.round(r.x_d[-1, :3], 4)}")


if __name__ == "__main__":
    main(*map(float, sys.argv[1:3]))

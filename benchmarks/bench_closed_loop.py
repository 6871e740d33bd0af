"""Cost of one control period of the thesis' control architecture (Fig. 3.4), in-process.

The stages of cdpr_control.control_loop (the code each node runs) against the simulator, for both
robots holding a circle set-point: the real-time factor of controller + simulator, the simulator
alone on the same commands (baseline, same run), and the median cost of each stage. The node graph
itself (ROS transport, composed and one process per node) is measured by bench_graph.py.

Writes bench/closed_loop.json. Run: .venv/bin/python benchmarks/bench_closed_loop.py
"""
from __future__ import annotations

import json
import pathlib
import platform
import time

import numpy as np

from cdpr_control.control_loop import ControlLoop
from cdpr_control.kernels import inverse_kinematics
from cdpr_control.robot import load_robot
from cdpr_sim.simulator import SimConfig, Simulator
from cdpr_sim.startup import startup_state

PERIOD = 1e-3
STEPS = 3000
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "closed_loop.json"


def circle(robot, k):
    """A circle in the x-z plane at 0.5 Hz starting at home, with its twist."""
    w = 2 * np.pi * 0.5
    t = k * PERIOD
    r = 0.02 * robot.frame_size[0]            # 2.2 cm on the Mini, 34 cm on the IPAnema 3
    x = robot.home + np.array([r * np.sin(w * t), 0, r * (1 - np.cos(w * t)), 0, 0, 0])
    xd = np.array([r * w * np.cos(w * t), 0, r * w * np.sin(w * t), 0, 0, 0])
    xdd = np.array([-r * w * w * np.sin(w * t), 0, r * w * w * np.cos(w * t), 0, 0, 0])
    return x, xd, xdd


def timed(fn, *args):
    t0 = time.perf_counter_ns()
    out = fn(*args)
    return out, time.perf_counter_ns() - t0


def bench(name: str) -> dict:
    robot = load_robot(name)
    x0, theta0, offset = startup_state(robot, robot.home, 0.0, calibrate_home=True)
    loop = ControlLoop(robot, PERIOD)
    parts = {k: [] for k in ("ik_x_d_us", "friction_us", "forward_kinematics_us", "force_setpoint_us", "cfc_us", "ospc_us",
                              "joint_command_us", "simulator_us")}
    commands = []
    with Simulator(robot, SimConfig(), x0=x0, theta0=theta0, encoder_offset=offset) as sim:
        out = sim.output
        loop.command.reset(out.theta)
        wall0 = time.perf_counter()
        for k in range(STEPS):
            x_d, xd, xdd = circle(robot, k)
            ik_d, t0 = timed(inverse_kinematics, robot, x_d)
            f, t1 = timed(loop.friction.update, out.F_s, out.theta, out.thetadot, ik_d.beta)
            (x, w), t2 = timed(loop.estimator.update, out.theta, f, x_d, ik_d)
            dist, t3 = timed(loop.force.update, x_d, xd, xdd, w, ik_d.AT)
            dq, t4 = timed(loop.cfc.update, dist.f, f, out.theta, dist.f_min, dist.f_max)
            x_ospc, t5 = timed(loop.ospc.update, x_d, x)
            theta_d, t6 = timed(loop.command.update, x_d, [x_ospc], dq)
            out, t7 = timed(sim.step, theta_d)
            commands.append(theta_d)
            for key, t in zip(parts, (t0, t1, t2, t3, t4, t5, t6, t7)):
                parts[key].append(t / 1e3)
        wall = time.perf_counter() - wall0
    x0, theta0, offset = startup_state(robot, robot.home, 0.0, calibrate_home=True)
    with Simulator(robot, SimConfig(), x0=x0, theta0=theta0, encoder_offset=offset) as sim:
        t0 = time.perf_counter()
        for theta_d in commands:
            sim.step(theta_d)
        sim_wall = time.perf_counter() - t0
    controller = {k: float(np.median(v)) for k, v in parts.items() if k != "simulator_us"}
    return {
        "rtf": STEPS * PERIOD / wall,
        "baseline_simulator_alone_rtf": STEPS * PERIOD / sim_wall,
        "controller_median_us": float(np.median(np.sum([parts[k] for k in controller], axis=0))),
        "stage_median_us": controller,
    }


def main() -> None:
    result = {"machine": platform.processor() or platform.machine(), "steps": STEPS,
              "robots": {name: bench(name) for name in ("ipanema3_mini", "ipanema3")}}
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()

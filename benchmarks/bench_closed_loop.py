"""Cost of one control period of the thesis' control architecture (Fig. 3.4), in-process.

The stages of cdpr_control.control.loop (the code each node runs) against the simulator, for both
robots on a circle set-point, twice in the same run: with the compiled kernels
(cdpr_control.kernels, the default) and on the numpy reference (``kernels.numpy_reference()``,
today's baseline). For each: the median cost of each stage per period, the median of their sum
(``controller_median_us``, the figure of the issue's target <= 100 us), the safety monitor that
ControlLoop.step runs besides, and the real-time factor of controller + simulator; the simulator
alone on the same commands is the baseline of the RTF. ``ik_x_d_us`` is the IK of x_d as
ControlLoop.step takes it since session 10: the fields of one computation the stages share
(kernels.inverse_kinematics_fields; the force set-point's A^T of the same x_d is then no second IK),
before it the full kernels.inverse_kinematics handed to the estimator. The CFC is given x_d, as
ControlLoop.step gives it. ``shipped_params``: the IPAnema 3 once more with its parameter file
(control_loop_params: among others the CFC's internal integral, CFCParams.internal_integral, whose
integral part projects onto the nullspace of A^T(x_d) every period while x_d moves), compiled and on
the numpy reference; the other runs take the dataclass defaults. ``startup_s`` is the time a fresh process
takes to import the kernels and load them from the on-disk cache (kernels.warm_up). The node graph
itself (ROS transport, composed and one process per node) is measured by bench_graph.py.

Plant: the simulator with its default SimConfig on the robot file's nominal parameters.
Writes bench/closed_loop.json. Run: .venv/bin/python benchmarks/bench_closed_loop.py
"""
from __future__ import annotations

import contextlib
import json
import pathlib
import platform
import subprocess
import sys
import time

import numpy as np

from cdpr_control import kernels
from cdpr_control.control.loop import ControlLoop
from cdpr_control.control.params import control_loop_params
from cdpr_control.model.robot import load_robot
from cdpr_sim.simulator import SimConfig, Simulator
from cdpr_sim.startup import startup_state

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from timing import python_calibration_us  # noqa: E402

PERIOD = 1e-3
STEPS = 3000
TARGET_US = 100.0
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "closed_loop.json"
STAGES = ("ik_x_d_us", "friction_us", "forward_kinematics_us", "force_setpoint_us", "cfc_us", "ospc_us",
          "joint_command_us")


def circle(robot, k):
    """A circle in the x-z plane at 0.5 Hz starting at home, with its twist."""
    w = 2 * np.pi * 0.5
    t = k * PERIOD
    r = 0.02 * robot.frame_size[0]            # 2.2 cm on the Mini, 34 cm on the IPAnema 3
    x = robot.home + np.array([r * np.sin(w * t), 0, r * (1 - np.cos(w * t)), 0, 0, 0])
    xd = np.array([r * w * np.cos(w * t), 0, r * w * np.sin(w * t), 0, 0, 0])
    xdd = np.array([-r * w * w * np.sin(w * t), 0, r * w * w * np.cos(w * t), 0, 0, 0])
    return x, xd, xdd


def timed(fn, *args, **kwargs):
    t0 = time.perf_counter_ns()
    out = fn(*args, **kwargs)
    return out, time.perf_counter_ns() - t0


def run(robot, compiled: bool, params=None) -> tuple[dict, list]:
    """STEPS periods of the stages of ControlLoop.step, each timed; -> (figures, commands).
    ``params``: the ControlLoopParams (None: the dataclass defaults)."""
    mode = contextlib.nullcontext() if compiled else kernels.numpy_reference()
    with mode:
        x0, theta0, offset = startup_state(robot, robot.home, 0.0, calibrate_home=True)
        loop = ControlLoop(robot, PERIOD, params)
        parts = {k: [] for k in STAGES + ("safety_monitor_us",)}
        commands = []
        with Simulator(robot, SimConfig(), x0=x0, theta0=theta0, encoder_offset=offset) as sim:
            out = sim.output
            loop.command.reset(out.theta)
            wall0 = time.perf_counter()
            for k in range(STEPS):
                x_d, xd, xdd = circle(robot, k)
                ik_d, t0 = timed(kernels.setpoint_ik, robot, x_d)   # as ControlLoop.step
                f, t1 = timed(loop.friction.update, out.F_s, out.theta, out.thetadot, ik_d.beta)
                (x, w), t2 = timed(loop.estimator.update, out.theta, f, x_d, ik_d)
                dist, t3 = timed(loop.force.update, x_d, xd, xdd, w, AT=ik_d.AT)
                dq, t4 = timed(loop.cfc.update, dist.f, f, out.theta, dist.f_min, dist.f_max, x_d=x_d)
                x_ospc, t5 = timed(loop.ospc.update, x_d, x)
                _, t_safety = timed(loop.monitor.check, out.t, f=f, f_min=robot.cable.f_min,
                                    f_max=robot.cable.f_max, x_d=x_d, x=x,
                                    fk_converged=loop.estimator.result.converged)
                theta_d, t6 = timed(loop.command.update, x_d, [x_ospc], dq)
                out = sim.step(theta_d)
                commands.append(theta_d)
                for key, t in zip(parts, (t0, t1, t2, t3, t4, t5, t6, t_safety)):
                    parts[key].append(t / 1e3)
            wall = time.perf_counter() - wall0
    stage = {k: float(np.median(parts[k])) for k in STAGES}
    return {
        "controller_median_us": float(np.median(np.sum([parts[k] for k in STAGES], axis=0))),
        "controller_p99_us": float(np.percentile(np.sum([parts[k] for k in STAGES], axis=0), 99)),
        "stage_median_us": stage,
        "safety_monitor_median_us": float(np.median(parts["safety_monitor_us"])),
        "rtf": STEPS * PERIOD / wall,
    }, commands


def simulator_alone_rtf(robot, commands) -> float:
    x0, theta0, offset = startup_state(robot, robot.home, 0.0, calibrate_home=True)
    with Simulator(robot, SimConfig(), x0=x0, theta0=theta0, encoder_offset=offset) as sim:
        t0 = time.perf_counter()
        for theta_d in commands:
            sim.step(theta_d)
        return STEPS * PERIOD / (time.perf_counter() - t0)


def shipped(name: str) -> dict:
    """The robot with its parameter file (control_loop_params), compiled and on the reference."""
    robot = load_robot(name)
    params = control_loop_params(robot)
    compiled, _ = run(robot, compiled=True, params=params)
    reference, _ = run(robot, compiled=False, params=params)
    return {"internal_integral": params.cfc.internal_integral, "compiled": compiled,
            "numpy_reference": reference, "speedup": reference["controller_median_us"] / compiled["controller_median_us"]}


def bench(name: str) -> dict:
    robot = load_robot(name)
    compiled, commands = run(robot, compiled=True)
    reference, _ = run(robot, compiled=False)
    return {
        "compiled": compiled,
        "numpy_reference": reference,
        "speedup": reference["controller_median_us"] / compiled["controller_median_us"],
        "baseline_simulator_alone_rtf": simulator_alone_rtf(robot, commands),
    }


def startup_s() -> float:
    """A fresh interpreter: import the kernels and load them for the Mini from the disk cache."""
    code = ("import time; t = time.perf_counter(); from cdpr_control import kernels; "
            "from cdpr_control.model.robot import load_robot; kernels.warm_up(load_robot('ipanema3_mini')); "
            "print(time.perf_counter() - t)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    startup_s()                                  # compiles on a machine that never ran the kernels
    result = {"machine": platform.processor() or platform.machine(), "steps": STEPS,
              "python_calibration_us": python_calibration_us(),
              "target_controller_median_us": TARGET_US,
              "startup_s": startup_s(),
              "robots": {name: bench(name) for name in ("ipanema3_mini", "ipanema3")},
              "shipped_params": {"ipanema3": shipped("ipanema3")}}
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()

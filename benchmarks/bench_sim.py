"""Real-time factor and per-step cost of the simulator (cdpr_sim.simulator.Simulator) at 1 kHz.

For both robots the platform follows a 5 cm circle (so the pulley IK refreshes, the winches reverse
and the friction model iterates) with the commands precomputed. Measured in the same run:
* the full Simulator.step, wall time and process CPU time, and its real-time factor (1 ms / step);
* the same with the pulley friction off (what the friction model costs);
* the parts of a step, each timed alone on the live objects: physics (pybullet step, state read,
  force application), cable model, drives, friction, sensors (force AD + encoders), and publishing
  one period on the ROS topics of the node (no subscriber);
* baseline: a bare pybullet step of one rigid body of the same mass with 8 external forces.

Writes bench/sim.json. Run: .venv/bin/python benchmarks/bench_sim.py
"""
from __future__ import annotations

import json
import pathlib
import platform
import time

import numpy as np
import pybullet

from cdpr_control import kernels
from cdpr_control.model.robot import load_robot
from cdpr_sim.simulator import SimConfig, Simulator, pretension_lengths
from cdpr_sim.startup import startup_forces

PERIOD = 1e-3
STEPS = 4000
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "sim.json"


def stats(samples_ns) -> dict:
    us = np.asarray(samples_ns, dtype=float) / 1e3
    return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99))}


def commands(robot, n: int) -> np.ndarray:
    """theta_d of a 5 cm circle in the x-z plane at 0.5 Hz under the QP forces of tension level 0.5."""
    t = PERIOD * np.arange(n)
    out = np.empty((n, robot.m))
    for k in range(n):
        x = robot.home.copy()
        x[0] += 0.05 * np.sin(np.pi * t[k])
        x[2] += 0.05 * (1.0 - np.cos(np.pi * t[k]))
        out[k] = pretension_lengths(robot, x, startup_forces(robot, x, 0.5))
    return out


def run_steps(sim: Simulator, theta_d: np.ndarray, x0, repeats: int = 3) -> dict:
    """The command sequence from the start pose, ``repeats`` times; figures of the fastest run.

    The machine is shared: the fastest of a few runs is the least disturbed one. rtf is simulated
    time over wall time, rtf_cpu over process CPU time, rtf_median 1 ms over the median step.
    """
    best = None
    for _ in range(repeats):
        sim.reset(x0, theta_d[0])
        samples = np.empty(len(theta_d), dtype=np.int64)
        cpu0, wall0 = time.process_time(), time.perf_counter()
        for k, td in enumerate(theta_d):
            t0 = time.perf_counter_ns()
            sim.step(td)
            samples[k] = time.perf_counter_ns() - t0
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        sim_time = len(theta_d) * PERIOD
        run = {**stats(samples), "rtf": sim_time / wall, "rtf_cpu": sim_time / cpu,
               "rtf_median": PERIOD / (float(np.median(samples)) * 1e-9), "steps": len(theta_d)}
        if best is None or run["rtf"] > best["rtf"]:
            best = run
    return best


def time_call(fn, n: int = 3000) -> float:
    """Median wall time of fn() [us] over n calls."""
    samples = np.empty(n, dtype=np.int64)
    for k in range(n):
        t0 = time.perf_counter_ns()
        fn()
        samples[k] = time.perf_counter_ns() - t0
    return float(np.median(samples)) / 1e3


def parts(sim: Simulator, theta_d: np.ndarray) -> dict:
    """Each part of a step timed alone on the objects of a running simulator."""
    body, cables, drives, client = sim._body, sim.cables, sim.drives, sim._client
    r, R, v, omega = body.state()
    F, T = np.zeros(3), np.zeros(3)
    out = sim.output
    thetadot = np.zeros(sim.m)

    def sensor_force():                 # what Simulator.step runs: the kernel unless the kernels are off
        if kernels.ENABLED:
            return kernels.friction_sensor_force(sim.friction, out.f, drives.theta, thetadot, cables.beta)
        return sim.friction.sensor_force(out.f, drives.theta, thetadot, cables.beta)

    physics = (time_call(lambda: pybullet.stepSimulation(physicsClientId=client)) + time_call(body.state)
               + time_call(lambda: body.apply(F, T, r)))
    return {
        "physics_us": physics,
        "cable_model_us": time_call(lambda: cables.wrench(r, R, v, omega, drives.theta, drives.thetadot)),
        "drives_us": time_call(lambda: drives.step(theta_d)),
        "friction_us": time_call(sensor_force),
        "sensors_us": time_call(lambda: sim.sensor.read(out.F_s_true)) + time_call(lambda: sim.encoder.read(out.theta_true)),
    }


def publishing_us(robot_name: str) -> float:
    """One period on the node's topics (winch/state, /clock, 4 ground-truth topics), no subscriber."""
    import rclpy
    from rclpy.parameter import Parameter

    from cdpr_sim.nodes.winch_platform_sim import WinchPlatformSimNode

    rclpy.init()
    try:
        node = WinchPlatformSimNode(parameter_overrides=[Parameter("robot", value=robot_name)])
        us = time_call(node._publish, 2000)
        node.destroy_node()
    finally:
        rclpy.shutdown()
    return us


def bare_pybullet(mass: float, n: int = STEPS) -> dict:
    """Baseline: one free rigid body, 8 external forces per step, 1 ms steps."""
    client = pybullet.connect(pybullet.DIRECT)
    pybullet.setTimeStep(PERIOD, physicsClientId=client)
    pybullet.setGravity(0, 0, -9.81, physicsClientId=client)
    shape = pybullet.createCollisionShape(pybullet.GEOM_SPHERE, radius=0.05, physicsClientId=client)
    body = pybullet.createMultiBody(mass, shape, physicsClientId=client)
    samples = np.empty(n, dtype=np.int64)
    force = [0.0, 0.0, mass * 9.81 / 8]
    wall0 = time.perf_counter()
    for k in range(n):
        t0 = time.perf_counter_ns()
        for _ in range(8):
            pybullet.applyExternalForce(body, -1, force, [0.0, 0.0, 0.0], pybullet.WORLD_FRAME, physicsClientId=client)
        pybullet.stepSimulation(physicsClientId=client)
        pybullet.getBasePositionAndOrientation(body, physicsClientId=client)
        samples[k] = time.perf_counter_ns() - t0
    wall = time.perf_counter() - wall0
    pybullet.disconnect(client)
    return {**stats(samples), "rtf": n * PERIOD / wall}


def bench_robot(name: str) -> dict:
    robot = load_robot(name)
    theta_d = commands(robot, STEPS)
    results = {}
    for label, friction in (("full", True), ("no_friction", False)):
        sim = Simulator(robot, SimConfig(period=PERIOD, friction=friction), x0=robot.home, theta0=theta_d[0])
        sim.step(theta_d[0])                                   # compile/warm up
        results[label] = run_steps(sim, theta_d, robot.home)
        if friction:
            results["parts"] = parts(sim, theta_d[-1])
        sim.close()
    results["parts"]["publishing_us"] = publishing_us(name)
    results["baseline_bare_pybullet"] = bare_pybullet(robot.platform.mass)
    return results


def main() -> None:
    report = {
        "what": "cdpr_sim Simulator.step at 1 kHz (one physics step per period), 5 cm circle, QP pre-tension",
        "machine": {"python": platform.python_version(), "processor": platform.processor() or platform.machine()},
        "robots": {name: bench_robot(name) for name in ("ipanema3", "ipanema3_mini")},
    }
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(report, indent=2) + "\n")
    for name, r in report["robots"].items():
        print(f"{name}: rtf {r['full']['rtf']:.1f} (cpu {r['full']['rtf_cpu']:.1f}, median "
              f"{r['full']['rtf_median']:.1f}), without friction "
              f"{r['no_friction']['rtf']:.1f}; bare pybullet rtf {r['baseline_bare_pybullet']['rtf']:.0f}; "
              + ", ".join(f"{k} {v:.1f}" for k, v in r["parts"].items()))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()

"""Robot model benchmark: inverse kinematics (single pose and batch) and the elastic forward
kinematics (3.7)-(3.9) warm-started along a 1 kHz trajectory, against scipy.optimize.least_squares
on the same residual. Writes bench/model.json.

Run: .venv/bin/python benchmarks/bench_model.py
"""

from __future__ import annotations

import gc
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
import scipy
from scipy.optimize import least_squares

from cdpr_control.model import cable
from cdpr_control.model.dynamics import platform_wrench
from cdpr_control.model.forward_kinematics import ForwardKinematics
from cdpr_control.model.kinematics import inverse_kinematics, twist_from_pose_rates
from cdpr_control.model.robot import load_robot
from timing import python_calibration_us

ROOT = Path(__file__).resolve().parents[1]

RATE_HZ = 1000.0
DURATION_S = 2.0
LAG_S = 0.002  # the actual platform trails the desired pose: the FK's warm-start error
TARGET_FK_MEDIAN_US = 100.0
TARGET_IK_CABLES_PER_S = 1e6
# circle radius [m] and frequency [Hz] of the test trajectory per robot
TRAJECTORY = {"ipanema3": (0.5, 0.5), "ipanema3_mini": (0.08, 1.0)}


def timed(fn, repeats):
    """Per-call wall times [us] of fn() (garbage collector paused, as in a real-time loop)."""
    gc.collect()
    gc.disable()
    try:
        out = []
        for _ in range(repeats):
            t0 = time.perf_counter_ns()
            fn()
            out.append((time.perf_counter_ns() - t0) / 1e3)
    finally:
        gc.enable()
    return np.array(out)


def stats(us):
    return {
        "median_us": float(np.median(us)),
        "p99_us": float(np.percentile(us, 99)),
        "max_us": float(us.max()),
    }


def bench_ik(robot, rng):
    lo, hi = robot.workspace_min, robot.workspace_max
    X = np.hstack([rng.uniform(lo, hi, (10000, 3)), rng.uniform(-0.2, 0.2, (10000, 3))])
    single = timed(lambda: inverse_kinematics(robot, X[0]), 3000)
    loop_s = min(timed(lambda: [inverse_kinematics(robot, x) for x in X[:1000]], 3)) / 1e6
    out = {
        "single_pose": {
            **stats(single),
            "poses_per_s": 1e6 / float(np.median(single)),
            "cable_lengths_per_s": robot.m * 1e6 / float(np.median(single)),
        },
        "loop_of_single_poses_baseline": {
            "poses_per_s": 1000 / loop_s,
            "cable_lengths_per_s": robot.m * 1000 / loop_s,
        },
    }
    for n in (1000, 10000):
        batch_s = min(timed(lambda: inverse_kinematics(robot, X[:n]), 10)) / 1e6
        out[f"batch_{n}"] = {
            "poses_per_s": n / batch_s,
            "cable_lengths_per_s": robot.m * n / batch_s,
        }
    return out


def trajectory(robot):
    """Desired poses at 1 kHz (circle plus an orientation wobble) and the lagging actual poses."""
    radius, freq = TRAJECTORY[robot_key(robot)]
    t = np.arange(0.0, DURATION_S, 1.0 / RATE_HZ)

    def pose(t):
        w = 2 * np.pi * freq
        x = np.zeros((t.size, 6))
        x[:, 0] = radius * np.cos(w * t)
        x[:, 1] = radius * np.sin(w * t)
        x[:, 3] = 0.03 * np.sin(w * t)
        x[:, 5] = 0.03 * np.cos(w * t)
        return x + robot.home

    return pose(t), pose(t - LAG_S)


def robot_key(robot):
    return Path(robot.file).stem


def simulated_measurements(robot, x_act):
    """Winch lengths and cable forces of the platform held by elastic cables at the actual poses:
    forces balancing the platform wrench (closed-form distribution around the mid force)."""
    dt = 1.0 / RATE_HZ
    dx = np.gradient(x_act, dt, axis=0)
    ddx = np.gradient(dx, dt, axis=0)
    xdot, xddot = twist_from_pose_rates(x_act, dx, ddx)
    w = platform_wrench(robot, x_act, xdot, xddot)
    ik = inverse_kinematics(robot, x_act)
    f_mid = 0.5 * (robot.cable.f_min + robot.cable.f_max)
    AT = ik.AT
    f = f_mid - np.einsum("nij,nj->ni", np.linalg.pinv(AT), np.einsum("nij,j->ni", AT, f_mid) + w)
    assert np.all(f > 0.0), "test trajectory leaves the tensed workspace"
    theta = ik.q - cable.elongation_from_force(robot, f, cable.total_free_length(robot, ik.q))
    return theta, f


def scipy_elastic_fk(fk, robot, theta, f, x_d):
    """The same problem as ForwardKinematics.elastic(pulleys='frozen'), solved by MINPACK's LM."""
    dq = cable.elongation_from_force_and_winch_length(robot, f, theta)
    q_hat = theta + dq
    k_l = cable.stiffness(robot, f, cable.total_free_length(robot, q_hat))
    ik_d = inverse_kinematics(robot, x_d)
    residual = fk._frozen_residual(
        np.ascontiguousarray(ik_d.c.T), q_hat - ik_d.beta * robot.r_p, k_l
    )
    cache = {}

    def fun(x):
        cache["x"], (cache["r"], cache["JT"]) = x.copy(), residual(x)
        return cache["r"]

    def jac(x):
        if not np.array_equal(x, cache.get("x")):
            fun(x)
        return cache["JT"].T

    return least_squares(fun, x_d, jac=jac, method="lm", xtol=1e-10, ftol=1e-15, gtol=1e-15)


def anchor_error(robot, x, y):
    """Largest distance [m] between platform anchor points B_i at poses x and y (rows)."""
    return float(
        np.max(
            np.linalg.norm(
                inverse_kinematics(robot, x).Rb
                + x[:, None, :3]
                - inverse_kinematics(robot, y).Rb
                - y[:, None, :3],
                axis=-1,
            )
        )
    )


def bench_fk(robot):
    fk = ForwardKinematics(robot)
    x_des, x_act = trajectory(robot)
    theta, f = simulated_measurements(robot, x_act)
    ik_des = [inverse_kinematics(robot, x) for x in x_des]
    out = {
        "trajectory": {
            "rate_hz": RATE_HZ,
            "samples": len(x_des),
            "circle_radius_m": TRAJECTORY[robot_key(robot)][0],
            "circle_frequency_hz": TRAJECTORY[robot_key(robot)][1],
            "lag_s": LAG_S,
            "max_warm_start_error_m": anchor_error(robot, x_des, x_act),
        }
    }
    variants = {
        "elastic_frozen_pulleys": lambda k: fk.elastic(theta[k], f[k], x_des[k]),
        "elastic_frozen_pulleys_ik_d_given": lambda k: fk.elastic(
            theta[k], f[k], x_des[k], ik_d=ik_des[k]
        ),
        "elastic_full_pulleys": lambda k: fk.elastic(theta[k], f[k], x_des[k], pulleys="full"),
    }
    for name, solve in variants.items():
        results, times = [], []
        gc.collect()
        gc.disable()
        for k in range(len(x_des)):
            t0 = time.perf_counter_ns()
            res = solve(k)
            times.append((time.perf_counter_ns() - t0) / 1e3)
            results.append(res)
        gc.enable()
        X = np.array([r.x for r in results])
        out[name] = {
            **stats(np.array(times)),
            "all_converged": all(r.converged for r in results),
            "mean_iterations": float(np.mean([r.iterations for r in results])),
            "max_anchor_error_m": anchor_error(robot, X, x_act),
        }
    times, X, conv, nfev = [], [], [], []
    gc.collect()
    gc.disable()
    for k in range(len(x_des)):
        t0 = time.perf_counter_ns()
        res = scipy_elastic_fk(fk, robot, theta[k], f[k], x_des[k])
        times.append((time.perf_counter_ns() - t0) / 1e3)
        X.append(res.x)
        conv.append(res.status > 0)
        nfev.append(res.nfev)
    gc.enable()
    out["baseline_scipy_least_squares_lm_frozen_pulleys"] = {
        **stats(np.array(times)),
        "all_converged": bool(all(conv)),
        "mean_function_evaluations": float(np.mean(nfev)),
        "max_anchor_error_m": anchor_error(robot, np.array(X), x_act),
    }
    out["speedup_vs_scipy_median"] = (
        out["baseline_scipy_least_squares_lm_frozen_pulleys"]["median_us"]
        / out["elastic_frozen_pulleys"]["median_us"]
    )
    return out


def main():
    rng = np.random.default_rng(0)
    report = {
        "machine": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "cpu_count": os.cpu_count(),
            "load_average_1min": os.getloadavg()[0],
            "python_calibration_us": python_calibration_us(),
            "note": "python_calibration_us: sum(range(1000)); ~10-15 us on an idle core",
        },
        "targets": {
            "fk_median_us": TARGET_FK_MEDIAN_US,
            "ik_batch_cable_lengths_per_s": TARGET_IK_CABLES_PER_S,
        },
    }
    for name in ("ipanema3", "ipanema3_mini"):
        robot = load_robot(name)
        report[name] = {"ik": bench_ik(robot, rng), "fk_1khz": bench_fk(robot)}
    r3 = report["ipanema3"]
    report["targets_met"] = {
        "fk_median_us": bool(
            r3["fk_1khz"]["elastic_frozen_pulleys"]["median_us"] <= TARGET_FK_MEDIAN_US
        ),
        "ik_batch_cable_lengths_per_s": bool(
            r3["ik"]["batch_10000"]["cable_lengths_per_s"] >= TARGET_IK_CABLES_PER_S
        ),
    }
    report["machine"]["python_calibration_us_after"] = python_calibration_us()
    out = ROOT / "bench" / "model.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()

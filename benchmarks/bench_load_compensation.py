"""Cost of one period of the load identification and compensation (4.4)-(4.6), per robot.

LoadCompensation.update (moving averages, the secant offset of (4.5)-(4.6), output filter; also
with the cable settlement model on) on a
circle set-point with the forces that carry it, beside two baselines of the same run: the OSPC
update (one PI per DOF, the other offset input of the joint command) and the IK of x_d (which the
control loop shares with this stage). Figures in microseconds (median), plus the machine's
calibration loop (benchmarks/timing.py) to compare runs on a loaded machine.

Writes bench/load_compensation.json. Run: .venv/bin/python benchmarks/bench_load_compensation.py
"""
from __future__ import annotations

import json
import pathlib
import platform
import time

import numpy as np
from timing import python_calibration_us

from cdpr_control.model.dynamics import platform_wrench
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.control.load_compensation import LoadCompensation, LoadCompensationParams
from cdpr_control.control.ospc import OperationalSpacePositionController, OSPCParams
from cdpr_control.model.robot import load_robot

STEPS = 2000
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "load_compensation.json"


def bench(name: str, params: LoadCompensationParams | None = None) -> dict:
    robot = load_robot(name)
    lc = LoadCompensation(robot, 1e-3, params or LoadCompensationParams())
    ospc = OperationalSpacePositionController(OSPCParams(), 1e-3)
    r = 0.02 * robot.frame_size[0]
    w = np.pi
    samples, times = [], {"load_compensation_us": [], "ospc_us": [], "inverse_kinematics_us": []}
    for k in range(STEPS):
        t = k * 1e-3
        x = robot.home + np.array([r * np.sin(w * t), 0, r * (1 - np.cos(w * t)), 0, 0, 0])
        xd = np.array([r * w * np.cos(w * t), 0, r * w * np.sin(w * t), 0, 0, 0])
        xdd = np.array([-r * w * w * np.sin(w * t), 0, r * w * w * np.cos(w * t), 0, 0, 0])
        samples.append((x, xd, xdd))
    for x, xd, xdd in samples:
        t0 = time.perf_counter_ns()
        ik = inverse_kinematics(robot, x)
        t1 = time.perf_counter_ns()
        f = -np.linalg.pinv(ik.AT) @ platform_wrench(robot, x, xd, xdd) + 2.0 * robot.cable.f_min
        t2 = time.perf_counter_ns()
        lc.update(x, xd, xdd, f, x, ik)
        t3 = time.perf_counter_ns()
        ospc.update(x, x)
        t4 = time.perf_counter_ns()
        times["inverse_kinematics_us"].append((t1 - t0) / 1e3)
        times["load_compensation_us"].append((t3 - t2) / 1e3)
        times["ospc_us"].append((t4 - t3) / 1e3)
    out = {k.replace("_us", "_median_us"): float(np.median(v[100:])) for k, v in times.items()}
    out["load_compensation_over_ospc"] = out["load_compensation_median_us"] / out["ospc_median_us"]
    return out


def main():
    result = {"python_calibration_us": python_calibration_us(), "machine": platform.machine(),
              "robots": {name: bench(name) for name in ("ipanema3_mini", "ipanema3")}}
    # with the cable settlement model on (identified parameters, docs/load_compensation.md)
    result["ipanema3_settlement_model"] = bench("ipanema3", LoadCompensationParams(settlement_ratio=0.3))
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=1))
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()

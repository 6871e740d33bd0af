"""Hybrid position/force control benchmark: what one control period of the HPFC costs, beside the
OSPC (3.16) and the CFC (3.19)-(3.23) stages of the same loop as baselines measured in the same run.

- ``HybridForceControl.update`` in state D (task frame (5.2), contact force, PID (5.3));
- ``CFCCoupling.update`` (the coupling without the structure matrix, used in state I);
- what the node ``cable_force_controller`` adds per period under hybrid force control in D:
  ``kernels.inverse_kinematics(robot, x_d)``, ``task_force_direction`` and ``CFCCoupling.run``;
  and what ``hybrid_force_controller`` adds: ``ContactHandOver.update``;
- baselines: ``OperationalSpacePositionController.update`` and ``CableForceControl.update``.

Writes bench/hybrid_force.json. Run: .venv/bin/python benchmarks/bench_hybrid_force.py
"""
from __future__ import annotations

import gc
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from cdpr_control import kernels
from cdpr_control.control.cable_force_control import CableForceControl
from cdpr_control.control.hybrid_force_control import (CFCCoupling, ContactHandOver, HybridForceControl,
    task_force_direction)
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.control.ospc import OperationalSpacePositionController, OSPCParams
from cdpr_control.model.robot import load_robot
from timing import python_calibration_us

ROOT = Path(__file__).resolve().parents[1]
CALLS = 5000
DT = 1e-3


def timed(fn, calls=CALLS) -> np.ndarray:
    """Per-call wall times [us] of fn(k) (garbage collector paused, as in a real-time loop)."""
    out = np.empty(calls)
    gc.disable()
    try:
        for k in range(calls):
            t0 = time.perf_counter_ns()
            fn(k)
            out[k] = (time.perf_counter_ns() - t0) / 1e3
    finally:
        gc.enable()
    return out


def figures(us: np.ndarray) -> dict:
    return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99))}


def main() -> None:
    robot = load_robot("ipanema3")
    rng = np.random.default_rng(0)
    weight = robot.platform.mass * robot.gravity
    w = np.r_[weight + [0.0, 0.0, 500.0], 0.0, 0.0, 0.0] + rng.normal(0.0, 2.0, (CALLS, 6))
    F_d0 = np.array([0.0, 0.0, -500.0])

    hpfc = HybridForceControl(robot, DT, enabled=True)
    hpfc.state, hpfc.x_t, hpfc.integrator = "D", 0.05, 0.05          # in contact: the PID path
    coupling = CFCCoupling(2.0, DT)
    f_d = np.full((CALLS, robot.m), 300.0) + rng.normal(0.0, 1.0, (CALLS, robot.m))
    ospc = OperationalSpacePositionController(OSPCParams(), DT)
    x_d = robot.home
    x = x_d + rng.normal(0.0, 1e-4, (CALLS, 6))
    cfc = CableForceControl(robot, DT)
    theta = inverse_kinematics(robot, x_d).q
    f = f_d + rng.normal(0.0, 2.0, f_d.shape)
    c = robot.cable

    coupled = CableForceControl(robot, DT)
    coupled.update(f_d[0], f[0], theta, c.f_min, c.f_max)             # calibrated (dq_0 set)
    coupling_d = CFCCoupling(2.0, DT)
    z_t = np.array([0.0, 0.0, -1.0])

    def node_cfc_in_contact(k):
        a = task_force_direction(kernels.inverse_kinematics(robot, x_d).AT, z_t)
        coupling_d.run("D", f_d[k], a, coupled.controller, f[k])

    hand_over = ContactHandOver(0.3, DT)
    state_d = hpfc.update(F_d0, w[0])
    kernels.inverse_kinematics(robot, x_d)                              # compiled before timing

    calibration = python_calibration_us()
    results = {
        "hpfc_update_state_D": figures(timed(lambda k: hpfc.update(F_d0, w[k]))),
        "cfc_coupling_update": figures(timed(lambda k: coupling.update("D" if k % 2 else "I", f_d[k]))),
        "cfc_node_contact_ik_and_coupling_run": figures(timed(node_cfc_in_contact)),
        "contact_hand_over_update": figures(timed(lambda k: hand_over.update(state_d, 12600.0, True))),
        "baseline_ospc_update": figures(timed(lambda k: ospc.update(x_d, x[k]))),
        "baseline_cfc_update": figures(timed(lambda k: cfc.update(f_d[k], f[k], theta, c.f_min, c.f_max))),
    }
    results["hpfc_over_ospc"] = results["hpfc_update_state_D"]["median_us"] / results["baseline_ospc_update"]["median_us"]
    results["hpfc_over_cfc"] = results["hpfc_update_state_D"]["median_us"] / results["baseline_cfc_update"]["median_us"]
    report = {"robot": robot.name, "calls": CALLS, "python_calibration_us": calibration,
              "machine": platform.machine(), "cpus": os.cpu_count(), "results": results}
    out = ROOT / "bench" / "hybrid_force.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(report, indent=2))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()

"""Cost of the admittance controller per control period (thesis 5.2), beside the OSPC update.

The admittance controller's step (user wrench (5.9), zone, exact virtual system of six axes) for
an IPAnema 3 Mini pushed through its three zones, and the OSPC's PI update (3.16) on the same
machine in the same run as the baseline (both run once per period in their nodes).

Writes bench/admittance.json. Run: .venv/bin/python benchmarks/bench_admittance.py
"""
from __future__ import annotations

import json
import pathlib
import platform
import time

import numpy as np

from cdpr_control.control.admittance import AdmittanceController
from cdpr_control.model.dynamics import gravity_wrench
from cdpr_control.control.ospc import OperationalSpacePositionController, OSPCParams
from cdpr_control.model.robot import load_robot
from timing import python_calibration_us

PERIOD = 1e-3
STEPS = 5000
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "admittance.json"


def main() -> None:
    robot = load_robot("ipanema3_mini")
    controller = AdmittanceController(robot, PERIOD)
    controller.enable()
    ospc = OperationalSpacePositionController(OSPCParams(), PERIOD)
    w_g = gravity_wrench(robot, robot.home)
    setpoint = (robot.home.copy(), np.zeros(6), np.zeros(6))
    adm_us, ospc_us, zones = [], [], set()
    for k in range(STEPS):
        push = 12.0 if k < 300 else 4.0 if k < 3000 else -5.0            # zone 1 -> 2 -> 3 -> back
        w = w_g + np.r_[push, 0, 0, 0, 0, 0]
        t0 = time.perf_counter_ns()
        out = controller.step(w, *setpoint)
        t1 = time.perf_counter_ns()
        ospc.update(setpoint[0], out.x)
        t2 = time.perf_counter_ns()
        setpoint = (out.x, *out.twist())
        zones.add(out.zone)
        adm_us.append((t1 - t0) / 1e3)
        ospc_us.append((t2 - t1) / 1e3)
    adm, base = float(np.median(adm_us)), float(np.median(ospc_us))
    result = {"machine": platform.processor() or platform.machine(), "steps": STEPS,
              "zones_visited": sorted(int(z) for z in zones),
              "admittance_step_median_us": adm, "baseline_ospc_update_median_us": base,
              "ratio_to_baseline": adm / base, "python_calibration_us": python_calibration_us()}
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()

"""CPU time per period of the force set-point (ForceSetpoint.update) with and without a guiding user,
the figures of docs/admittance.md ("Cost per guided period"). A guided path about home: the pose
swings by 10 mm (Mini) / 100 mm (IPAnema 3) in x and y, the hand's wrench of 0.65 w_max (8.45 N /
42.25 N, w_max 13 N / 65 N here) turns in the x-y plane with a fifth of it along z; the measured wrench is
the model's with 0.2 N noise. CPU time (time.process_time) over the periods after the first 200,
so a busy machine stretches it less than wall time.

    .venv/bin/python scripts/hand_reserve_cpu.py [--periods 6000]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from cdpr_control.control.force_setpoint import ForceSetpoint
from cdpr_control.control.params import control_loop_params
from cdpr_control.model.dynamics import platform_wrench
from cdpr_control.model.robot import load_robot

DT = 1e-3
WARM_UP = 200          # periods before the clock starts (the solvers' first set-ups)
PATH = {"ipanema3_mini": (0.01, 13.0), "ipanema3": (0.1, 65.0)}   # m swing, N w_max of the hand


def guided_inputs(robot, periods: int, swing: float, w_max: float):
    """((x, xdot), measured wrench, the user's wrench) per period of the guided path."""
    rng = np.random.default_rng(0)
    home, zero = np.asarray(robot.home, dtype=float), np.zeros(6)
    for k in range(periods):
        t = k * DT
        x = home + swing * np.r_[np.sin(np.pi * t), 0.5 * np.sin(0.6 * np.pi * t), 0, 0, 0, 0]
        xdot = swing * np.r_[np.pi * np.cos(np.pi * t), 0.3 * np.pi * np.cos(0.6 * np.pi * t), 0, 0, 0, 0]
        w = platform_wrench(robot, x, xdot, zero) + rng.normal(0.0, 0.2, 6)
        yield (x, xdot), w, 0.65 * w_max * np.r_[np.cos(t), np.sin(t), 0.2, 0, 0, 0]


def cpu_per_period(name: str, guided: bool, periods: int) -> float:
    robot = load_robot(name)
    fs = ForceSetpoint(robot, DT, control_loop_params(robot).force)
    inputs = list(guided_inputs(robot, periods, *PATH[name]))
    zero = np.zeros(6)
    for k, ((x, xdot), w, w_user) in enumerate(inputs):
        if k == WARM_UP:
            c0 = time.process_time()
        fs.set_user_wrench(w_user if guided else None)
        fs.update(x, xdot, zero, w)
    return (time.process_time() - c0) / (periods - WARM_UP)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=6000)
    args = ap.parse_args()
    for name in PATH:
        alone, guided = (cpu_per_period(name, g, args.periods) for g in (False, True))
        print(f"{name}: {1e6 * alone:.0f} us nobody guiding, {1e6 * guided:.0f} us guided, "
              f"the reserve {1e6 * (guided - alone):.0f} us (CPU per period)")


if __name__ == "__main__":
    main()

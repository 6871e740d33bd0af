"""``cdpr analyze energy``: energy per subsystem and power over time, thesis section 4.4.

    cdpr analyze energy BAG [--robot NAME] [--sensor] [--plot PNG] [--json FILE]
    cdpr analyze energy --trajectory PROGRAM [--start X Y Z [A B C]] [--payload KG]
                        [--v-max V] [--a-max A] [--j-max J] [--plot PNG] [--json FILE]
    cdpr analyze energy --winch-map PNG [--robot NAME]

A bag needs ``winch/state`` (theta) and ``ground_truth/pose`` or ``setpoint``; the forces at the
platform come from ``ground_truth/cable_forces`` when recorded (the simulator), else (or with
``--sensor``) from the sensor forces F_s through the friction compensation (3.44). A trajectory is
evaluated at the minimal, medium and maximal tension level (Fig. 4.33) without a bag.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def bag_power(bag, robot, sensor: bool = False):
    """(PowerFlow, poses x (N, 6), forces f (N, m)) of a recorded run (cdpr_tools.bag.BagReader)."""
    from cdpr_control.analysis.energy import run_power
    from cdpr_control.control.friction_compensation import FrictionCompensation

    from cdpr_tools.identify import bag_data
    from cdpr_tools.identify.experiments import TOPIC_FORCES
    from cdpr_tools.identify.friction import wrap_angles

    w = bag_data.winch_state(bag)
    x = bag_data.poses(bag, w.t)
    if TOPIC_FORCES in bag.topics and not sensor:
        f = bag_data.reference_forces(bag, w.t)
    else:
        beta = wrap_angles(robot, x)
        stage = FrictionCompensation(robot, float(np.median(np.diff(w.t))))
        f = np.array([stage.update(*row) for row in zip(w.F_s, w.theta, w.thetadot, beta)])
    return run_power(robot, w.t, w.theta, f, x), x, f


def record_lift(bag_path, robot="ipanema3_mini", height: float = 0.1, velocity: float = 0.2,
                payload: float = 0.0, pause: float = 0.3, level: float = 0.0, lower: bool = True,
                seed: int = 1) -> Path:
    """Record with the simulator a lift of ``height`` m from home (and, with ``lower``, back down),
    IK-only control: a run with work done on (and by) the platform, for the energy analysis."""
    from cdpr_control.model.kinematics import inverse_kinematics
    from cdpr_control.model.robot import load_robot

    from cdpr_tools.identify.experiments import record_run, smooth_moves

    robot = load_robot(robot) if isinstance(robot, str) else robot
    top = np.array(robot.home, dtype=float)
    top[2] += height
    x_d = smooth_moves([robot.home, top, robot.home] if lower else [robot.home, top], velocity, pause, 1e-3)
    commands = inverse_kinematics(robot, x_d).q
    return record_run(robot, bag_path, commands, x_d, seed, None, level, (payload, (0.0, 0.0, 0.0)) if payload else None)


def _report(label: str, flow) -> dict:
    from cdpr_control.analysis.energy import summary

    s = summary(flow)
    print(f"{label}: {s['duration_s']:.2f} s, E_el {s['E_el_Wh']:.3f} Wh, peak P_el {s['P_el_peak_W']:.0f} W, "
          f"mean {s['P_el_mean_W']:.0f} W")
    print(f"  platform {s['E_mech_Wh']:+.3f} Wh | losses: pulleys {s['E_pulley_Wh']:.3f}, winches {s['E_winch_Wh']:.3f}, "
          f"servo {s['E_servo_Wh']:.3f}, cabinet {s['E_cabinet_Wh']:.3f} Wh | DC-link exchange {s['E_rec_Wh']:.3f} Wh")
    print("  loss shares: " + ", ".join(f"{k[2:]} {100 * v:.1f} %" for k, v in s["loss_shares"].items()))
    return s


def main(argv=None) -> int:
    from cdpr_control.model.robot import load_robot

    p = argparse.ArgumentParser(prog="cdpr analyze energy",
                                description="Energy model (4.9)-(4.14): a recorded run or a planned trajectory.")
    p.add_argument("bag", nargs="?", help="recorded run (omit with --trajectory)")
    p.add_argument("--robot", default=None, help="robot name or YAML (default: ipanema3 for --trajectory, "
                   "ipanema3_mini for a bag)")
    p.add_argument("--sensor", action="store_true", help="forces from F_s via friction compensation, not ground truth")
    p.add_argument("--trajectory", metavar="PROGRAM", help="G-code program: shipped name (e.g. reference_trip_ipanema3) or file")
    p.add_argument("--start", type=float, nargs="+", metavar="X", help="start pose x y z [a b c] (default: robot home)")
    p.add_argument("--payload", type=float, default=0.0, help="payload on the platform [kg] (trajectory)")
    p.add_argument("--v-max", type=float, default=1.5, help="path velocity limit [m/s] (default 1.5, Fig. 4.34)")
    p.add_argument("--a-max", type=float, default=5.0, help="path acceleration limit [m/s^2] (default 5)")
    p.add_argument("--j-max", type=float, default=20.0, help="path jerk limit [m/s^3] (default 20)")
    p.add_argument("--plot", metavar="PNG", help="power over time and losses per subsystem")
    p.add_argument("--json", metavar="FILE", help="write the summary as JSON")
    p.add_argument("--winch-map", metavar="PNG", help="winch efficiency map (4.15), Fig. 4.32")
    args = p.parse_args(argv)
    from cdpr_control import programs
    from cdpr_control.motion.program import GCodeError
    from cdpr_control.analysis.energy import (LEVELS, REFERENCE_TRIP, THESIS_REFERENCE_TRIP, plot,
                                              plot_winch_efficiency, program_motion, trajectory_power)

    if args.winch_map:
        robot = load_robot(args.robot or "ipanema3")
        plot_winch_efficiency(robot, args.winch_map)
        print(f"wrote {args.winch_map}")
        if args.bag is None and args.trajectory is None:
            return 0
    if (args.bag is None) == (args.trajectory is None):
        p.error("give either a BAG or --trajectory PROGRAM")

    results, flows = {}, {}
    if args.bag:
        from cdpr_tools.bag import BagReader

        from cdpr_tools.identify.bag_data import run_title

        robot = load_robot(args.robot or "ipanema3_mini")
        bag = BagReader(args.bag)
        flow, _, _ = bag_power(bag, robot, args.sensor)
        results["run"], flows["run"] = _report(args.bag, flow), flow
        title = f"Energy (4.9)-(4.14): {run_title(bag, robot)}"
    else:
        robot = load_robot(args.robot or "ipanema3")
        start = np.array(robot.home, dtype=float)
        if args.start:
            if len(args.start) not in (3, 6):
                p.error("--start takes 3 or 6 numbers")
            start[:len(args.start)] = args.start
        try:
            _, program = programs.source(args.trajectory)
        except GCodeError as exc:                     # bytes that are not UTF-8: where, in the file
            raise ValueError(f"{args.trajectory}:{exc.diagnostics[0]}") from None
        motion = program_motion(program, start, args.v_max, args.a_max, args.j_max)
        for name, level in LEVELS.items():
            te = trajectory_power(robot, motion, level, args.payload)
            if not te.feasible.all():
                print(f"{name} tension: no feasible forces at {int((~te.feasible).sum())} of {len(te.feasible)} samples")
            results[name], flows[name] = _report(f"{name} tension (level {level})", te.flow), te.flow
        if args.trajectory == REFERENCE_TRIP.program:
            thesis = THESIS_REFERENCE_TRIP
            print(f"thesis, reference trip at minimal tension (section 4.4.3): {thesis['energy_Wh']} Wh, "
                  f"peak about {thesis['peak_power_W'] / 1e3:g} kW")
        title = f"Energy (4.9)-(4.14): {robot.name}, planned trajectory {args.trajectory}, payload {args.payload:g} kg"
        medium = results["medium"]["E_el_Wh"]
        print("relative to medium tension (Fig. 4.33): " + ", ".join(
            f"{k} {100 * (r['E_el_Wh'] / medium - 1):+.1f} %" for k, r in results.items()))
    if args.plot:
        plot(flows, args.plot, title)
        print(f"wrote {args.plot}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
        print(f"wrote {args.json}")
    return 0

"""``cdpr demo``: the project's main job.

The IPAnema 3 Mini (or another robot) in the lockstep simulator runs a shipped G-code program
through the whole node graph of Fig. 3.4 (graphs/closed_loop.yaml: OSPC + CFC, QP at minimal
tension), composed in one process; every topic is recorded to a bag under bags/. Then it prints
the pose error against the simulator's ground truth, the cable forces against their limits, the
real-time factor and the bag path, and writes PNG plots next to the bag.

It exits 1 and says why when the run did not do what it was for: the program failed, the safety
layer held the robot for good (a latched hold of the joint command on /diagnostics: the force
watch, a lost input, the workspace left; a transient hold, such as a lag, is printed only),
or the run diverged (a true cable force beyond DIVERGENCE_FACTOR f_max, or not finite), even when
the program itself reached its end.
"""
from __future__ import annotations

import json
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from cdpr_control import programs
from cdpr_control.model.robot import load_robot

GRAPH = Path(__file__).parent / "graphs" / "closed_loop.yaml"
BAGS = Path(__file__).resolve().parents[2] / "bags"
DEFAULT_PROGRAM = {"ipanema3_mini": "cuboid_mini", "ipanema3": "rectangle"}
#: the surface a contact program (hybrid position/force control, section 5.1) presses on
PROGRAM_SURFACE = {"floor_contact_ipanema3": "floor", "cylinder_contact_force": "cylinder"}
DIVERGENCE_FACTOR = 1.5      # a true cable force beyond this times f_max: the run diverged (as cdpr validate)


def add_parser(sub) -> None:
    p = sub.add_parser("demo", help="run the main job: a G-code program through the simulated closed loop, recorded")
    p.add_argument("--robot", default="ipanema3_mini", help="shipped robot name (default: ipanema3_mini)")
    p.add_argument("--program", help="G-code file or shipped program name (default: cuboid_mini for the Mini)")
    p.add_argument("--mode", choices=("composed", "processes"), default="composed", help="how to run the graph")
    p.add_argument("--controller", choices=("force_control", "ik_only"), default="force_control",
                   help="joint_command mode: the thesis' force control or the IK-only reference")
    p.add_argument("--plant", choices=("mismatched", "nominal"), default="mismatched",
                   help="the simulated robot: its own parameters (default) or the robot file itself")
    p.add_argument("--surface", choices=("auto", "none", "floor", "cylinder"), default="auto",
                   help="contact surface in the simulator: floor 10 mm below the tool tip at home, or the "
                        "barrel of cylinder_contact_force (r = 180 mm + 20 mm tool at the platform origin); "
                        "auto: the one the program needs")
    p.add_argument("--contact-stiffness", type=float, default=1e6, help="surface stiffness [N/m] (damping 1 %% of it)")
    p.add_argument("--output", help="bag directory (default: bags/demo_<robot>_<date-time>)")
    p.add_argument("--timeout", type=float, default=900.0, help="wall-clock limit for the program, and for the graph to take it [s]")
    p.set_defaults(run=run)


def program_text(robot_name: str, program: str | None) -> tuple[str, str]:
    return programs.source(program or DEFAULT_PROGRAM.get(robot_name, "rectangle"))


def surface_parameters(robot, surface: str, stiffness: float) -> dict:
    """Parameters of winch_platform_sim that place a contact surface (docs/hybrid_force_control.md)."""
    if surface == "none":
        return {}
    from cdpr_sim.contacts import default_tool
    material = {"contact_stiffness": stiffness, "contact_damping": 0.01 * stiffness, "contact_friction": 0.3}
    if surface == "floor":
        radius, centre = default_tool(robot.b)
        return {"floor": True, "floor_height": float(robot.home[2] + centre[2] - radius - 0.01), **material}
    return {"cylinder": True, "cylinder_center": [0.0, 0.0, -0.28], "cylinder_axis": [1.0, 0.0, 0.0],
            "cylinder_radius": 0.18, "cylinder_length": 0.9, "platform_shape": "sphere", "tool_radius": 0.02,
            "tool_offset": [0.0, 0.0, 0.0], **material}


def run(args) -> int:
    import rclpy.logging

    from cdpr_tools.launch import Launcher, RecordSpec
    from cdpr_tools.progress import Progress
    from cdpr_tools.launch_file import load_launch_file
    from cdpr_tools.program_client import run_program
    from cdpr_tools.run_report import plot_run, read_bag, summarize

    robot = load_robot(args.robot)
    name, text = program_text(args.robot, args.program)
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    bag = Path(args.output) if args.output else BAGS / f"demo_{args.robot}_{stamp}"
    description = load_launch_file(GRAPH, {"robot": args.robot})
    description.record = RecordSpec(output=str(bag))
    surface = PROGRAM_SURFACE.get(name, "none") if args.surface == "auto" else args.surface
    for spec in description.nodes:
        if spec.module.endswith("joint_command"):
            spec.parameters.append({"mode": args.controller})
        if spec.module.endswith("winch_platform_sim"):
            spec.parameters.append({"plant": args.plant})
            spec.parameters.append(surface_parameters(robot, surface, args.contact_stiffness))
    print(f"[demo] {robot.name} ({args.plant} plant): program {name!r} through the node graph ({args.mode}, {args.controller}), "
          f"recording to {bag}", flush=True)
    wall0 = time.perf_counter()
    # the console shows the program's progress: the recorder's line per subscribed topic is left out
    rclpy.logging.set_logger_level("bag_recorder", rclpy.logging.LoggingSeverity.WARN)
    with Launcher(description, mode=args.mode) as launch:   # composed: held until the recorder records
        if args.mode == "processes":
            _wait_for_recorder(launch)  # the children run at once; the recorder discovers them meanwhile
        progress = Progress(f"[demo] program {name!r}")
        # the graph is the demo's own: its answer to the goal (the interpreter plans and checks the
        # program first, between the loop's periods) may take as long as the program may; on a busy
        # machine that took more than the 30 s a client of a running graph waits
        result = run_program(text, name, timeout=args.timeout, server_timeout=args.timeout,
                             feedback=lambda line, p: progress.update(p, f"line {line}"))
        progress.done()
        wall = time.perf_counter() - wall0
        errors = list(launch.errors)
    if errors:
        print("[demo] the graph reported errors: " + "; ".join(errors))
    if not result.success:
        print(f"[demo] program failed: {result.message}")
        return 1
    data = read_bag(bag)
    latched, transient = holds(bag)
    problems = run_problems(data, latched)
    summary = summarize(data)
    summary.update({"program": name, "robot": args.robot, "controller": args.controller, "mode": args.mode,
                    "program_duration_s": result.duration, "wall_time_s": wall,
                    "real_time_factor": data.t[-1] / wall, "bag": str(bag)})
    plots = plot_run(data, bag.parent, prefix=f"{bag.name}_",
                     title=f"{robot.name}, {args.controller}, {args.plant} plant, bag {bag.name}")
    (bag.parent / f"{bag.name}_summary.json").write_text(json.dumps(summary, indent=2))
    print(f"[demo] pose error: RMS {summary['position_error_rms_mm']:.3f} mm, max {summary['position_error_max_mm']:.3f} mm; "
          f"orientation RMS {summary['orientation_error_rms_deg']:.4f} deg, max {summary['orientation_error_max_deg']:.4f} deg")
    print(f"[demo] cable forces: {summary['cable_force_min_N']:.2f} .. {summary['cable_force_max_N']:.2f} N "
          f"(limits {summary['f_min_N']:.1f} .. {summary['f_max_N']:.1f} N; periods below f_min: "
          f"{summary['samples_below_f_min']}, above f_max: {summary['samples_above_f_max']})")
    print(f"[demo] {data.t[-1]:.2f} s simulated in {wall:.1f} s wall: real-time factor {summary['real_time_factor']:.2f}")
    print(f"[demo] bag: {bag}")
    print("[demo] plots: " + ", ".join(str(p) for p in plots))
    if transient:
        print(f"[demo] the joint command held while a fault lasted ({transient[0]}"
              f"{f'; {len(transient) - 1} more' if len(transient) > 1 else ''})")
    for problem in problems:
        print(f"[demo] run failed: {problem}")
    return 1 if problems else 0


def holds(bag) -> tuple[list[str], list[str]]:
    """The holds the joint command reported on /diagnostics during the run, as "t = ... s: message"
    (each change once, as reported) -> (latched: the force watch, a lost input, the workspace left,
    which end the run; transient: a lag or a forward kinematics that did not converge, which hold
    while they last)."""
    from cdpr_tools.bag import BagReader

    reader = BagReader(bag)
    latched, transient = [], []
    for m in reader.messages([t for t in reader.topics if t == "/diagnostics"]):
        stamp = m.msg.header.stamp.sec + 1e-9 * m.msg.header.stamp.nanosec
        for status in m.msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if status.name.endswith("joint_command") and values.get("holding") == "True":
                (latched if values.get("abort") == "True" else transient).append(f"t = {stamp:.3f} s: {status.message}")
    return latched, transient


def run_problems(data, held: list[str]) -> list[str]:
    """Why a run whose program ended did not do what it was for: the safety layer held it for good
    (``held``: the latched holds of :func:`holds`), or a true cable force went beyond DIVERGENCE_FACTOR f_max or was not
    finite ([] when neither)."""
    problems = [f"the safety layer held the robot ({held[0]}{f'; {len(held) - 1} more' if len(held) > 1 else ''})"] \
        if held else []
    finite = np.isfinite(data.f).all(axis=1)
    beyond = np.flatnonzero(~finite | (data.f > DIVERGENCE_FACTOR * data.f_max).any(axis=1))
    if len(beyond):
        i = beyond[0]
        what = "not finite" if not finite[i] else f"{np.nanmax(data.f[i]):.4g} N > {DIVERGENCE_FACTOR} f_max"
        problems.append(f"diverged: cable force {what} at t = {data.t[i]:.3f} s")
    return problems


RECORDED = {"/winch/state", "/winch/command", "/setpoint", "/ground_truth/pose", "/ground_truth/cable_forces",
            "/cable_forces", "/force_distribution", "/platform/pose", "/cable_force_controller/state", "/ospc/state",
            "/hybrid_force_controller/state"}


def _wait_for_recorder(launch, timeout: float = 60.0) -> None:
    """Until the bag recorder subscribes to every loop topic (DDS discovery takes up to seconds)."""
    deadline = time.monotonic() + timeout
    while not RECORDED <= set(launch.recorder.recorded_topics):
        if time.monotonic() > deadline:
            missing = sorted(RECORDED - set(launch.recorder.recorded_topics))
            raise TimeoutError(f"the recorder did not find {', '.join(missing)} within {timeout:.0f} s")
        time.sleep(0.1)

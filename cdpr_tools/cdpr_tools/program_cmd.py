"""``cdpr program``: list the shipped G-code programs, check one, or run one on a running graph."""
from __future__ import annotations


from cdpr_control import programs
from cdpr_control.analysis.arguments import non_negative, positive
from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.program import GCodeError
from cdpr_control.motion.program_check import check_program
from cdpr_control.model.robot import load_robot
from cdpr_tools.progress import Progress
from cdpr_tools.ros_graph import DISCOVERY_TIMEOUT


def add_parser(sub) -> None:
    p = sub.add_parser("program", help="list, check or run G-code programs (dialect: docs/gcode.md)")
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    verbs.add_parser("list", help="shipped programs").set_defaults(run=_list)
    check = verbs.add_parser("check", help="parse and plan a program for a robot; every error with line:col",
                             description="Parse the program, plan its time law and check that its path "
                                         "stays in the robot's wrench-feasible workspace (with the payload); "
                                         "errors name line:col. The interpreter runs the same check before "
                                         "it starts a program.")
    check.add_argument("program", help="G-code file or shipped program name")
    check.add_argument("--robot", default="ipanema3_mini", help="robot name or file (default ipanema3_mini)")
    check.add_argument("--payload", type=float, default=0.0, help="payload carried [kg] (default 0)")
    check.set_defaults(run=_check)
    run = verbs.add_parser("run", help="run a program through the RunProgram action of a running graph")
    run.add_argument("program", help="G-code file or shipped program name")
    run.add_argument("--action", default="/run_program", help="action name (default /run_program)")
    run.add_argument("--timeout", type=positive, default=3600.0, metavar="SEC",
                     help="wall-clock limit from sending the program to its end [s] (default 3600)")
    run.add_argument("--server-timeout", type=non_negative, default=DISCOVERY_TIMEOUT, metavar="SEC",
                     help=f"wait up to SEC seconds for the graph's action server (default {DISCOVERY_TIMEOUT:g})")
    run.set_defaults(run=_run)


def _print_diagnostics(program: str, exc: GCodeError) -> int:
    for d in exc.diagnostics:
        print(f"{program}:{d}")
    return 1


def _list(args) -> int:
    for name in programs.names():
        print(name)
    return 0


def _check(args) -> int:
    robot = load_robot(args.robot)
    try:
        name, text = programs.source(args.program)
        program = parse_gcode(text, start_pose=robot.home)
        duration = check_program(program, robot, payload=args.payload)
    except GCodeError as exc:
        return _print_diagnostics(args.program, exc)
    print(f"{name}: ok for {robot.name}, {len(program.blocks)} blocks, {duration:.2f} s "
          "(at the interpreter's default limits)")
    return 0


def _run(args) -> int:
    from cdpr_tools.program_client import run_program

    try:
        name, text = programs.source(args.program)
    except GCodeError as exc:
        return _print_diagnostics(args.program, exc)
    # on a terminal one line rewritten in place; into a file or pipe a line per tenth of the program
    shown = Progress(f"program {name!r}")
    try:
        result = run_program(text, name, action=args.action, timeout=args.timeout, server_timeout=args.server_timeout,
                             feedback=lambda line, fraction: shown.update(fraction, f"line {line}"))
    except BaseException:
        shown.stop()
        raise
    if result.success:
        shown.done()
    else:
        shown.stop()
    print(f"{name}: {'done' if result.success else 'failed'} after {result.duration:.2f} s {result.message}")
    return 0 if result.success else 1

"""CPU time of each stage of the in-process loop on the held state, comparable across trees.

cdpr_sim.closed_loop.run holds the IPAnema 3 Mini at home (the default plant: mismatched, plant
seed 1, sensor seed 0) with the parameter file's configuration for ``--warm`` seconds; the
arguments of each stage's last call are kept, and each stage is then called again with them
``--number`` times, ``--repeat`` rounds, timed in the process's CPU time (``time.process_time``,
which other load on a shared machine inflates much less than wall time); the best round per call
is printed. The stages keep their state between the calls (a held loop: the same inputs each
period, as holding home gives them). ``loop.step`` is the whole period. The imports take either
layout, so the same program measures an older tree (784c4eb):

    PYTHONPATH=<tree>/cdpr_control:<tree>/cdpr_sim:<tree>/cdpr_tools python benchmarks/bench_stage_cpu.py

Stages absent in a tree (older ones) are left out. Writes nothing: docs/performance.md quotes it.
"""
from __future__ import annotations

import argparse
import copy
import importlib
import time
import timeit

try:
    from cdpr_control.model.robot import load_robot
    importlib.import_module("cdpr_control.control.loop")
except ImportError:                                     # the layout before 708a2ce
    from cdpr_control.robot import load_robot
from cdpr_sim.closed_loop import hold, run

ROBOT = "ipanema3_mini"
STAGES = {  # label -> (the ControlLoop attribute, its method)
    "friction": ("friction", "update"), "estimator": ("estimator", "update"), "hpfc": ("hpfc", "update"),
    "force": ("force", "update"), "contact": ("contact", "update"), "cfc": ("cfc", "update"),
    "ospc": ("ospc", "update"), "monitor": ("monitor", "check"), "offsets": ("offsets", "update"),
    "watch": ("watch", "update"), "command": ("command", "update"),
}


def capture(calls: dict):
    """before_step of closed_loop.run: in the last periods, each stage's arguments (copied)."""
    holder = {}

    def before_step(k, loop, sim):
        if k:
            return
        holder["loop"] = loop
        for label, (attr, method) in STAGES.items():
            stage = getattr(loop, attr, None)
            if stage is None or not hasattr(stage, method):
                continue
            fn = getattr(stage, method)

            def wrapper(*args, _fn=fn, _label=label, **kwargs):
                calls[_label] = (_fn, copy.deepcopy(args), copy.deepcopy(kwargs))
                return _fn(*args, **kwargs)
            setattr(stage, method, wrapper)
        step = loop.step

        def step_wrapper(*args, **kwargs):
            calls["loop.step"] = (step, copy.deepcopy(args), copy.deepcopy(kwargs))
            return step(*args, **kwargs)
        loop.step = step_wrapper
    return before_step, holder


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--warm", type=float, default=0.5, help="s held before the timing")
    parser.add_argument("--number", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--only", nargs="+", help="these stages only")
    args = parser.parse_args()
    robot = load_robot(ROBOT)
    calls: dict = {}
    before_step, holder = capture(calls)
    run(robot, hold(robot.home), args.warm, before_step=before_step)
    loop = holder["loop"]
    for attr, method in [*STAGES.values(), (None, "step")]:      # the wrappers off: the stages' own calls
        stage = loop if attr is None else getattr(loop, attr, None)
        if stage is not None and method in vars(stage):
            delattr(stage, method)
    print(f"{ROBOT} holding home, default plant (mismatched, plant seed 1), process CPU, best of "
          f"{args.repeat} x {args.number} calls [us a call]")
    for label in [*STAGES, "loop.step"]:
        if label not in calls or (args.only and label not in args.only):
            continue
        fn, a, kw = calls[label]
        best = min(timeit.Timer(lambda: fn(*a, **kw), timer=time.process_time).repeat(args.repeat, args.number))
        print(f"{label:12s} {1e6 * best / args.number:8.2f}")


if __name__ == "__main__":
    main()

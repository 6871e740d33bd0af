"""Per-stage time of the in-process loop (bench_graph.py's ``baseline``), comparable across trees.

cdpr_sim.closed_loop.run holding the IPAnema 3 Mini at home (the default plant: mismatched, plant
seed 1, sensor seed 0) with the parameter file's configuration; each stage method ControlLoop.step
calls (and the simulator's step) is wrapped in a perf_counter_ns timer from the first period on,
and the median over the periods after the first tenth is printed, with the process CPU and wall
time per period of the whole run. Nested stages are timed inside their caller (``cfc`` inside
``contact``, the hybrid force control's CFC coupling); the wrappers add about 0.1-0.3 us each.
The imports take either layout, so the same program measures an older tree (784c4eb, before the
layout of Fig. 3.4):

    PYTHONPATH=<tree>/cdpr_control:<tree>/cdpr_sim:<tree>/cdpr_tools python benchmarks/bench_loop_stages.py

``--profile`` prints cProfile's 45 most expensive functions (own time) instead. ``--clock thread``
times each stage in the thread's CPU time (``time.thread_time_ns``) instead of wall time: on a
machine shared with other work a stage's wall time includes the periods the scheduler gave the
core to another process and the caches they left cold, its CPU time much less (each reading costs
a system call, about 0.3 us, inside the nested stages' figures too, in every tree alike). The
machine is shared: run the trees back to back, several times, and compare medians
(docs/performance.md).
"""
from __future__ import annotations

import argparse
import cProfile
import importlib
import pstats
import time

import numpy as np

try:
    from cdpr_control.model.robot import load_robot
    loop_module = importlib.import_module("cdpr_control.control.loop")
except ImportError:                                     # the layout before 708a2ce
    from cdpr_control.robot import load_robot
    loop_module = importlib.import_module("cdpr_control.control_loop")
from cdpr_sim.closed_loop import hold, run

ROBOT = "ipanema3_mini"
STAGES = {  # label -> (the ControlLoop attribute, its method); absent ones (older trees) are left out
    "ik_x_d": (None, "inverse_kinematics"), "friction": ("friction", "update"), "estimator": ("estimator", "update"),
    "hpfc": ("hpfc", "update"), "force": ("force", "update"), "set_user_wrench": ("force", "set_user_wrench"),
    "contact": ("contact", "update"), "cfc": ("cfc", "update"), "ospc": ("ospc", "update"),
    "monitor": ("monitor", "check"), "offsets": ("offsets", "update"), "watch": ("watch", "update"),
    "command": ("command", "update"),
}


class _Kernels:
    """The loop module's ``kernels`` with its IK of x_d timed (once a period: ``inverse_kinematics``
    up to session 9, the ``inverse_kinematics_fields`` the friction compensation takes since)."""

    def __init__(self, kernels, times, label):
        self._kernels = kernels
        self.inverse_kinematics = timed(times, label, kernels.inverse_kinematics)
        if hasattr(kernels, "inverse_kinematics_fields"):
            self.inverse_kinematics_fields = timed(times, label, kernels.inverse_kinematics_fields)

    def __getattr__(self, name):
        return getattr(self._kernels, name)


CLOCK = time.perf_counter_ns          # the stage timers' clock (--clock)


def timed(times: dict, label: str, fn):
    samples = times.setdefault(label, [])

    def wrapper(*args, **kwargs):
        t0 = CLOCK()
        out = fn(*args, **kwargs)
        samples.append(CLOCK() - t0)
        return out
    return wrapper


def instrument(times: dict):
    """before_step of closed_loop.run: wraps the stages in the first period."""
    def before_step(k, loop, sim):
        if k:
            return
        for label, (attr, method) in STAGES.items():
            if attr is None:
                kernels = loop_module.kernels
                loop_module.kernels = _Kernels(kernels, times, label)
                continue
            stage = getattr(loop, attr, None)
            if stage is not None and hasattr(stage, method):
                setattr(stage, method, timed(times, label, getattr(stage, method)))
        loop.step = timed(times, "loop.step", loop.step)
        sim.step = timed(times, "sim.step", sim.step)
    return before_step


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--periods", type=int, default=3000)
    parser.add_argument("--profile", action="store_true", help="cProfile (process CPU) instead of the stage timers")
    parser.add_argument("--clock", choices=("wall", "thread"), default="wall",
                        help="the stage timers' clock: wall time (perf_counter_ns) or the thread's CPU time (thread_time_ns)")
    args = parser.parse_args()
    global CLOCK
    CLOCK = time.thread_time_ns if args.clock == "thread" else time.perf_counter_ns
    robot = load_robot(ROBOT)
    run(robot, hold(robot.home), 0.2)                  # kernels loaded, caches warm
    duration = args.periods * 1e-3
    if args.profile:
        profile = cProfile.Profile(time.process_time)
        profile.runcall(run, robot, hold(robot.home), duration)
        pstats.Stats(profile).sort_stats("tottime").print_stats(45)
        return
    times: dict[str, list[int]] = {}
    kernels = loop_module.kernels
    cpu0, wall0 = time.process_time(), time.perf_counter()
    try:
        run(robot, hold(robot.home), duration, before_step=instrument(times))
    finally:
        loop_module.kernels = kernels
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    print(f"{ROBOT} holding home, default plant, {args.periods} periods, {args.clock} clock: "
          f"{1e6 * cpu / args.periods:.1f} us CPU, {1e6 * wall / args.periods:.1f} us wall a period")
    for label, samples in times.items():
        us = np.array(samples[len(samples) // 10:]) * 1e-3
        print(f"{label:16s} median {np.median(us):7.2f} us")


if __name__ == "__main__":
    main()

"""Checking a G-code program against a robot before it runs (thesis 2.2.1, 2.3.2).

A parsed program can still be impossible to run: its time law may not be plannable (a feed typo
making a move last hours), or its path may leave the wrench-feasible workspace (2.39)-(2.40), where
no cable forces within [f_min, f_max] hold the platform (its weight with the payload) and cables go
slack. :func:`check_program` plans the program, samples its path and reports the first block that
leaves the workspace, with its line, as a :class:`GCodeError` like the parser's. Before that it
refuses a payload the robot cannot hold at its home pose at all (:func:`payload_capacity`): then
no program can run, and the reason is the payload, not a line.
"""
from __future__ import annotations

import numpy as np

from cdpr_control.force_distribution import wrench_feasible
from cdpr_control.motion.program import Diagnostic, GCodeError, Program
from cdpr_control.motion.interpolation import Limits, sample_program
from cdpr_control.model.workspace import static_problem, with_platform_mass

CHECK_DT = 0.01   # s: sampling of the path for the check (the feed limits keep poses mm apart)


def payload_capacity(robot, x=None, rtol: float = 1e-4) -> float:
    """The largest payload [kg], at the platform's centre of gravity, that cable forces within
    [f_min, f_max] hold at rest at pose x (default the robot's home): the mass at which x leaves
    the wrench-feasible workspace (2.39)-(2.40). 0 if the platform alone is not held there.

    The weight is linear in the mass and the feasible masses at a pose form an interval, so a
    bisection on :func:`wrench_feasible` finds its end; it lies below sum(f_max) / |g| (all
    cables pulling straight up).
    """
    x = np.array(robot.home if x is None else x, dtype=float)
    AT, w_per_kg = static_problem(with_platform_mass(robot, 1.0), x[None])
    c = robot.cable

    def held(mass):
        return bool(wrench_feasible(AT, mass * w_per_kg, c.f_min, c.f_max)[0])

    lo = float(robot.platform.mass)
    if not held(lo):
        return 0.0
    hi = float(np.sum(np.broadcast_to(c.f_max, (robot.m,)))) / float(np.linalg.norm(robot.gravity)) * 1.01
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if held(mid) else (lo, mid)
    return lo - float(robot.platform.mass)


def payload_problem(robot, payload: float) -> str | None:
    """Why ``robot`` cannot carry ``payload`` [kg] (at its centre of gravity) at its home pose, or
    None when it can: the reason names the payload, the cable force limits and the capacity."""
    if payload <= 0.0:
        return None
    capacity = payload_capacity(robot)
    if payload <= capacity:
        return None
    c = robot.cable
    return (f"a payload of {payload:g} kg is beyond what {robot.name} can hold: at its home pose no cable forces "
            f"within [f_min, f_max] = [{np.min(c.f_min):g}, {np.max(c.f_max):g}] N hold "
            f"{robot.platform.mass + payload:g} kg (its capacity there is {capacity:.3g} kg of payload)")


def check_payload(robot, payload: float) -> None:
    """GCodeError (line 1, the payload as its text) when :func:`payload_problem` finds one."""
    reason = payload_problem(robot, payload)
    if reason is not None:
        raise GCodeError([Diagnostic(1, 1, f"payload {payload:g} kg", reason)])


def check_program(program: Program, robot, limits: Limits = Limits(), payload: float = 0.0,
                  dt: float = CHECK_DT) -> float:
    """The program's planned duration [s]; GCodeError naming the first line whose path leaves the
    wrench-feasible workspace of ``robot`` carrying ``payload`` [kg] (static, as Fig. 2.5)."""
    if not (np.isfinite(payload) and payload >= 0.0):
        raise ValueError(f"payload must be finite and >= 0 kg, got {payload}")
    check_payload(robot, payload)
    samples = sample_program(program, limits, dt)
    loaded = with_platform_mass(robot, robot.platform.mass + payload) if payload else robot
    AT, w = static_problem(loaded, samples.x)
    inside = wrench_feasible(AT, w, robot.cable.f_min, robot.cable.f_max)
    outside = np.flatnonzero(~inside)
    if outside.size:
        k = int(outside[0])
        x = samples.x[k]
        line = int(samples.line[k]) or 1
        raise GCodeError([Diagnostic(
            line, 1, "motion", f"the path leaves the wrench-feasible workspace of {robot.name}"
            + (f" with {payload:g} kg payload" if payload else "")
            + f" at x = [{x[0]:.3f}, {x[1]:.3f}, {x[2]:.3f}] m, t = {samples.t[k]:.2f} s: "
            "no cable forces within [f_min, f_max] hold the platform there")])
    return float(samples.t[-1])

"""Checking a G-code program against a robot before it runs (thesis 2.2.1, 2.3.2).

A parsed program can still be impossible to run: its time law may not be plannable (a feed typo
making a move last hours), or its path may leave the wrench-feasible workspace (2.39)-(2.40), where
no cable forces within [f_min, f_max] hold the platform (its weight with the payload) and cables go
slack. :func:`check_program` plans the program, samples its path and reports the first block that
leaves the workspace, with its line, as a :class:`GCodeError` like the parser's.
"""
from __future__ import annotations

import numpy as np

from .force_distribution import wrench_feasible
from .gcode_program import Diagnostic, GCodeError, Program
from .interpolation import Limits, sample_program
from .workspace import static_problem, with_platform_mass

CHECK_DT = 0.01   # s: sampling of the path for the check (the feed limits keep poses mm apart)


def check_program(program: Program, robot, limits: Limits = Limits(), payload: float = 0.0,
                  dt: float = CHECK_DT) -> float:
    """The program's planned duration [s]; GCodeError naming the first line whose path leaves the
    wrench-feasible workspace of ``robot`` carrying ``payload`` [kg] (static, as Fig. 2.5)."""
    if not (np.isfinite(payload) and payload >= 0.0):
        raise ValueError(f"payload must be finite and >= 0 kg, got {payload}")
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

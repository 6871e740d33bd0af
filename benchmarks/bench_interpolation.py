"""Cost of one interpolation cycle (Interpolator.step) on the sample programs, against ruckig's own
Ruckig.update() of a 1-DoF and a 6-DoF jerk-limited profile as baseline; plus parse time.

Writes bench/interpolation.json. Run: .venv/bin/python benchmarks/bench_interpolation.py
"""
from __future__ import annotations

import json
import pathlib
import time

import numpy as np
from ruckig import InputParameter, OutputParameter, Result, Ruckig

from cdpr_control import programs
from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.interpolation import TERMINAL_STATES, Interpolator, Limits

DT = 1e-3
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "interpolation.json"


def stats_us(samples_ns: list[int]) -> dict:
    us = np.asarray(samples_ns, dtype=float) / 1e3
    return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)), "cycles": len(us)}


def time_interpolator(name: str) -> dict:
    program = parse_gcode(programs.read(name))
    interp = Interpolator(program, Limits(), DT)
    samples = []
    while interp.state not in TERMINAL_STATES:
        t0 = time.perf_counter_ns()
        interp.step()
        samples.append(time.perf_counter_ns() - t0)
    return stats_us(samples)


def time_ruckig_update(dofs: int, cycles: int = 20000) -> dict:
    """Baseline: ruckig's online update from rest to a target, restarted whenever it finishes."""
    otg = Ruckig(dofs, DT)
    inp, out = InputParameter(dofs), OutputParameter(dofs)
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [0.5] * dofs, [2.0] * dofs, [20.0] * dofs
    samples = []
    target = 0.3
    inp.target_position = [target] * dofs
    for _ in range(cycles):
        t0 = time.perf_counter_ns()
        result = otg.update(inp, out)
        out.pass_to_input(inp)
        samples.append(time.perf_counter_ns() - t0)
        if result == Result.Finished:
            target = -target
            inp.target_position = [target] * dofs
    return stats_us(samples)


def time_parse(name: str, repeats: int = 50) -> dict:
    text = programs.read(name)
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        parse_gcode(text)
        samples.append(time.perf_counter_ns() - t0)
    lines = text.count("\n") + 1
    median_us = float(np.median(samples)) / 1e3
    return {"median_us": median_us, "lines": lines, "lines_per_s": lines / (median_us * 1e-6)}


def main() -> None:
    result = {
        "baseline_ruckig_update_1dof": time_ruckig_update(1),
        "baseline_ruckig_update_6dof": time_ruckig_update(6),
        "step": {name: time_interpolator(name) for name in programs.names()},
        "parse": {name: time_parse(name) for name in programs.names()},
        "dt_s": DT,
    }
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()

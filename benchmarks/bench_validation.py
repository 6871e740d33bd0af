"""The validation sweep of issue 25 (``cdpr validate``, docs/validation.md) as a benchmark area:
pass rate per case family, the worst case and where, and what the sweep cost.

The default sweep (both robots, four plants, 40 poses each, two processes), in process against
the simulator; the figures and the per-case JSON go to out/validation/. Beside the sweep's wall
time, the machine's calibration loop of the same run (benchmarks/timing.py), to compare runs on a
loaded machine. Arguments are passed to the sweep as to ``cdpr validate`` (e.g. ``--poses 6``).

Writes bench/validation.json. Run: .venv/bin/python benchmarks/bench_validation.py
"""
from __future__ import annotations

import argparse
import pathlib
import platform
import sys

from timing import python_calibration_us

from cdpr_tools.validate.cases import FAMILIES
from cdpr_tools.validate.report import HEADLINE, applicable, dumps
from cdpr_tools.validate.sweep import ROBOTS, plants, validate
from cdpr_tools.validate_cmd import _names, _seeds, add_parser

ROOT = pathlib.Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "validation.json"


def family_figures(s: dict, family: str) -> dict:
    """A family's summary: counts, pass rate, its headline metric's mean and worst case with where."""
    headline = s["metrics"].get(HEADLINE[family], {})
    return {"cases": s["cases"], "passed": s["passed"], "pass_rate": s["pass_rate"], "diverged": s["diverged"],
            "held": s["held"], "refused": s["refused"], "error": s["error"],
            "applicable": s["applicable"], "not_applicable": s["not_applicable"],
            "pass_rate_applicable": s["pass_rate_applicable"], "not_applicable_reasons": s["not_applicable_reasons"],
            "sag_below_resolution": s["sag_below_resolution"], "headline_metric": HEADLINE[family],
            "mean": headline.get("mean"), "worst": headline.get("worst"), "where": headline.get("where"),
            "not_measured": headline.get("not_measured", 0),
            "out_of_band": {k: m["out_of_band"] for k, m in s["metrics"].items() if m["out_of_band"]}}


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(prog="bench_validation")
    add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["validate", "--jobs", "2", "-o", str(ROOT / "out" / "validation"), *argv])
    calibration = python_calibration_us()
    results, doc, _ = validate(_names(args.robot, ROBOTS, "robot"), _names(args.family, FAMILIES, "family"),
                               plants(args.plant, _seeds(args.seeds)), args.poses, args.jobs, args.output,
                               command=" ".join(["benchmarks/bench_validation.py", *argv]))
    n_applicable = sum(applicable(r) for r in results)
    result = {"machine": platform.processor() or platform.machine(), "command": doc["meta"]["command"],
              "cases": len(results), "jobs": args.jobs, "sweep_wall_s": doc["meta"]["wall_s"],
              "sweep_cpu_s": doc["meta"]["cpu_s"],
              "pass_rate": sum(r.passed for r in results) / len(results),
              "pass_rate_applicable": (sum(r.passed for r in results) / n_applicable) if n_applicable else None,
              "not_applicable": len(results) - n_applicable,
              "families": {f: family_figures(s, f) for f, s in doc["summary"].items()},
              "per_robot_plant": doc["per_robot_plant"], "python_calibration_us": calibration,
              "report": str(pathlib.Path(args.output) / "validation.json")}
    OUT.parent.mkdir(exist_ok=True)
    text = dumps(result, indent=2)             # JSON without NaN: null where a metric was not measured
    OUT.write_text(text)
    print(text)


if __name__ == "__main__":
    main()

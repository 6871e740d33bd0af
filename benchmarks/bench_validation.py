"""The validation sweep of issue 25 (``cdpr validate``, docs/validation.md) as a benchmark area:
pass rate per case family (over the applicable cases and over all, with the counts), the worst case
and where of each family's main criteria, the same per robot and plant, and what the sweep cost.

The default sweep (both robots, four plants, 40 poses each, two processes), in process against
the simulator; the figures and the per-case JSON go to out/validation/. Beside the sweep's wall
time, the baseline of the same run: the machine's calibration loop (benchmarks/timing.py) before
and after the sweep, to compare runs on a loaded machine. Arguments are passed to the sweep as to
``cdpr validate`` (e.g. ``--poses 6``, ``--family program``); ``--from-cases FILE`` writes the
area from an earlier sweep's cases.jsonl instead of running one (its wall time: the cases' sum).

Writes bench/validation.json. Run: .venv/bin/python benchmarks/bench_validation.py
"""
from __future__ import annotations

import argparse
import json
import pathlib
import platform
import sys

from timing import python_calibration_us

from cdpr_tools.validate.cases import FAMILIES
from cdpr_tools.validate.figures import CRITERIA
from cdpr_tools.validate.report import HEADLINE, dumps, family_summary, plant_name, read_cases
from cdpr_tools.validate.sweep import ROBOTS, cpu_seconds, plants, validate
from cdpr_tools.validate_cmd import _names, _seeds, add_parser

ROOT = pathlib.Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "validation.json"


def family_figures(s: dict, family: str) -> dict:
    """A family's summary: counts, pass rates (applicable and all), its headline metric's mean and
    worst case with where, and the same for each of its main criteria (figures.CRITERIA)."""
    headline = s["metrics"].get(HEADLINE[family], {})
    return {"cases": s["cases"], "passed": s["passed"], "failed": s["failed"], "pass_rate": s["pass_rate"],
            "diverged": s["diverged"], "held": s["held"], "refused": s["refused"], "error": s["error"],
            "applicable": s["applicable"], "not_applicable": s["not_applicable"],
            "pass_rate_applicable": s["pass_rate_applicable"], "not_applicable_reasons": s["not_applicable_reasons"],
            "sag_below_resolution": s["sag_below_resolution"], "headline_metric": HEADLINE[family],
            "mean": headline.get("mean"), "worst": headline.get("worst"), "where": headline.get("where"),
            "not_measured": headline.get("not_measured", 0),
            "criteria": {m: {k: s["metrics"][m].get(k) for k in ("mean", "worst", "where", "out_of_band", "not_measured")}
                         for m in CRITERIA.get(family, ()) if m in s["metrics"]},
            "out_of_band": {k: m["out_of_band"] for k, m in s["metrics"].items() if m["out_of_band"]}}


def area(results, meta: dict, calibration: dict, report: str) -> dict:
    """bench/validation.json: the pass rates in total, per family and per robot and plant, beside
    the run's baseline (the calibration loop before and after the sweep)."""
    families = [f for f in HEADLINE if any(r.spec.family == f for r in results)]
    n_applicable = sum(r.status != "refused" for r in results)
    n_passed = sum(r.passed for r in results)
    per = {}
    for robot in sorted({r.spec.robot for r in results}):
        for plant in sorted({plant_name(r) for r in results if r.spec.robot == robot}):
            rs = [r for r in results if r.spec.robot == robot and plant_name(r) == plant]
            per[f"{robot} {plant}"] = {f: family_figures(family_summary(rs, f), f) for f in families
                                       if any(r.spec.family == f for r in rs)}
    return {"machine": platform.processor() or platform.machine(), "command": meta["command"],
            "cases": len(results), "passed": n_passed, "applicable": n_applicable,
            "not_applicable": len(results) - n_applicable, "jobs": meta.get("jobs"),
            "sweep_wall_s": meta["wall_s"], "sweep_cpu_s": meta["cpu_s"],
            "identification_wall_s": meta.get("identification_wall_s"),
            "pass_rate": n_passed / len(results) if results else None,
            "pass_rate_applicable": n_passed / n_applicable if n_applicable else None,
            "families": {f: family_figures(family_summary(results, f), f) for f in families},
            "per_robot_plant": per,
            "python_calibration_us": calibration["before"], "python_calibration_after_us": calibration["after"],
            "report": report}


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(prog="bench_validation")
    add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["validate", "--jobs", "2", "-o", str(ROOT / "out" / "validation"), *argv])
    command = " ".join(["benchmarks/bench_validation.py", *argv])
    calibration = {"before": python_calibration_us()}
    if args.from_cases:
        results = read_cases(args.from_cases)
        meta = {"command": f"{command} (the cases of an earlier sweep)",
                "wall_s": sum(r.wall_s for r in results), "cpu_s": cpu_seconds(results)}
        sweep = pathlib.Path(args.from_cases)
        sweep = (sweep if sweep.is_dir() else sweep.parent) / "validation.json"
        if sweep.is_file():                    # the sweep's own times (the cases' sum is not its wall time)
            swept = json.loads(sweep.read_text()).get("meta", {})
            meta.update({k: swept[k] for k in ("wall_s", "cpu_s", "identification_wall_s", "jobs") if k in swept})
        report = str(args.from_cases)
    else:
        results, doc, _ = validate(_names(args.robot, ROBOTS, "robot"), _names(args.family, FAMILIES, "family"),
                                   plants(args.plant, _seeds(args.seeds)), args.poses, args.jobs, args.output,
                                   command=command, friction_mode=args.friction)
        meta = doc["meta"]
        report = str(pathlib.Path(args.output) / "validation.json")
    calibration["after"] = python_calibration_us()
    result = area(results, meta, calibration, report)
    OUT.parent.mkdir(exist_ok=True)
    text = dumps(result, indent=2)             # JSON without NaN: null where a metric was not measured
    OUT.write_text(text)
    print(text)


if __name__ == "__main__":
    main()

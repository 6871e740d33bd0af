"""The controller stages of this tree against another tree's, interleaved period by period in one process.

``bench_closed_loop.py`` times the stages of ControlLoop.step against the simulator, one tree at a
time. On this shared two-core machine the speed of a whole process moves by 10-50 % from one minute
to the next (docs/performance.md), and even two processes started together on the two cores
differ by that much: the stages' 5 % criterion of issue 24 drowns in it. Here both trees run in
*one* process: each tree's packages are copied under names of their own (``cdpr_control_this``,
``cdpr_control_other``, the same for cdpr_sim; the code is not changed otherwise), and every period
runs one tree's stages and simulator step, then the other's (which goes first alternates), so
whatever the machine does, it does to both. Each tree's period is the body of the loop of its own
``benchmarks/bench_closed_loop.py`` (``run``): the calls its ControlLoop makes, timed per stage, on
the default plant along the benchmark's circle.

Per run and robot: the median per stage and of the stages' sum over STEPS periods (the first 200
left out), for each tree, and their ratio (this over other: below 1 is faster). A run is a process
of its own (memory layout and hash seeds move a process's figures by a few per cent); the figures
are the medians over the runs.

    .venv/bin/python benchmarks/bench_stages_against.py [--against REF] [--runs N] [--steps N]

REF is a git revision (default: ``CDPR_BENCH_AGAINST`` or HEAD; this tree is the working tree, so
against HEAD without changes it shows the instrument's own spread). Writes bench/stages_against.json.
Both trees' periods run one after the other, so each finds the cache after the other's period and
simulator step: the absolute figures are above bench_closed_loop's, the ratio is the comparison.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tempfile

from bench_against import OUT, ROOT, checked_out  # this folder, the script's own

ROBOTS = ("ipanema3_mini", "ipanema3")
SKIP = 200                          # periods left out at the start (the start-up ramp, first calls)

# The child: both trees' periods interleaved; prints the per-tree stage medians as JSON.
CHILD = r"""
import importlib, json, sys, textwrap
import numpy as np
pkgs, robot_name, steps, skip = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
sys.path.insert(0, pkgs)

def harness(tag):
    b = importlib.import_module(f"bench_{tag}")
    body = open(b.__file__).read().split("for k in range(STEPS):\n", 1)[1]
    body = textwrap.dedent(body[:body.index("out = sim.step(theta_d)")])
    ns = {"np": np}
    exec("def period(k, out, loop, robot, kernels, circle, timed):\n" + textwrap.indent(body, "    ")
         + "    return theta_d, (t0, t1, t2, t3, t4, t5, t6)\n", ns)
    robot = b.load_robot(robot_name)
    x0, theta0, offset = b.startup_state(robot, robot.home, 0.0, calibrate_home=True)
    loop = b.ControlLoop(robot, b.PERIOD)
    sim = b.Simulator(robot, b.SimConfig(), x0=x0, theta0=theta0, encoder_offset=offset).__enter__()
    loop.command.reset(sim.output.theta)
    return {"b": b, "period": ns["period"], "robot": robot, "loop": loop, "sim": sim, "out": sim.output, "t": []}

trees = {tag: harness(tag) for tag in ("this", "other")}
order = list(trees.values())
for k in range(steps):
    for h in (order if k % 2 == 0 else order[::-1]):
        b = h["b"]
        theta_d, times = h["period"](k, h["out"], h["loop"], h["robot"], b.kernels, b.circle, b.timed)
        h["out"] = h["sim"].step(theta_d)
        h["t"].append(times)
out = {}
for tag, h in trees.items():
    T = np.array(h["t"][skip:]) / 1e3
    out[tag] = {"stages_us": dict(zip(h["b"].STAGES, np.median(T, axis=0).tolist())),
                "controller_us": float(np.median(T.sum(axis=1)))}
print(json.dumps(out))
"""


def renamed_copy(tree: pathlib.Path, tag: str, pkgs: pathlib.Path) -> None:
    """tree's cdpr_control and cdpr_sim as cdpr_control_<tag>, cdpr_sim_<tag>, its closed-loop
    benchmark as bench_<tag>.py and its timing helper as timing_<tag>.py, imports renamed."""
    names = {"cdpr_control": f"cdpr_control_{tag}", "cdpr_sim": f"cdpr_sim_{tag}", "timing": f"timing_{tag}"}
    pattern = re.compile(r"\b(cdpr_control|cdpr_sim)\b")

    def rename(text: str) -> str:
        text = pattern.sub(lambda m: names[m.group(1)], text)
        return re.sub(r"^from timing import", f"from timing_{tag} import", text, flags=re.M)
    for package in ("cdpr_control", "cdpr_sim"):
        target = pkgs / names[package]
        shutil.copytree(tree / package / package, target, ignore=shutil.ignore_patterns("__pycache__"))
        for path in target.rglob("*.py"):
            path.write_text(rename(path.read_text(encoding="utf-8")), encoding="utf-8")
    bench = tree / "benchmarks"
    (pkgs / f"bench_{tag}.py").write_text(rename((bench / "bench_closed_loop.py").read_text()), encoding="utf-8")
    if (bench / "timing.py").exists():
        (pkgs / f"timing_{tag}.py").write_text((bench / "timing.py").read_text(), encoding="utf-8")


def run_child(pkgs: pathlib.Path, robot: str, steps: int) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(pkgs), robot, str(steps), str(SKIP)],
                         capture_output=True, text=True, timeout=3600)
    if out.returncode != 0 or not out.stdout.strip():
        raise RuntimeError(f"the interleaved stages failed (exit {out.returncode}):\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def summary(runs: list[dict]) -> dict:
    """Per stage and for the sum: the median over the runs of each tree's figure and of the ratio."""
    stages = list(runs[0]["this"]["stages_us"]) + ["controller"]

    def figure(run, tag, stage):
        return run[tag]["controller_us"] if stage == "controller" else run[tag]["stages_us"][stage]
    return {stage: {"this_us": statistics.median(figure(r, "this", stage) for r in runs),
                    "other_us": statistics.median(figure(r, "other", stage) for r in runs),
                    "ratio": statistics.median(figure(r, "this", stage) / figure(r, "other", stage) for r in runs)}
            for stage in stages}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", default=os.environ.get("CDPR_BENCH_AGAINST", "HEAD"),
                        help="git revision of the other tree (default: CDPR_BENCH_AGAINST or HEAD)")
    parser.add_argument("--runs", type=int, default=4, help="processes per robot")
    parser.add_argument("--steps", type=int, default=3000, help="periods per run")
    args = parser.parse_args()
    if args.runs < 1 or args.steps <= SKIP:
        parser.error(f"--runs must be at least 1 and --steps above {SKIP}")
    with checked_out(args.against) as (other, commit), tempfile.TemporaryDirectory(prefix="bench_stages_") as tmp:
        pkgs = pathlib.Path(tmp)
        renamed_copy(ROOT, "this", pkgs)
        renamed_copy(other, "other", pkgs)
        print("warm-up run (numba compiles both copies into their caches) ...", flush=True)
        run_child(pkgs, ROBOTS[0], SKIP + 10)
        runs = {robot: [] for robot in ROBOTS}
        for k in range(args.runs):
            for robot in ROBOTS:
                runs[robot].append(run_child(pkgs, robot, args.steps))
                r = runs[robot][-1]
                print(f"run {k + 1} {robot}: stages this {r['this']['controller_us']:.1f} us, other "
                      f"{r['other']['controller_us']:.1f} us, ratio "
                      f"{r['this']['controller_us'] / r['other']['controller_us']:.3f}", flush=True)
    result = {
        "machine": platform.machine(), "cpu_count": os.cpu_count(), "against": args.against, "against_commit": commit,
        "what": "ControlLoop's stages along bench_closed_loop's circle on the default plant, both trees "
                "interleaved period by period in one process; ratio this/other (below 1: faster)",
        "steps": args.steps, "runs": runs, "summary": {robot: summary(runs[robot]) for robot in ROBOTS},
    }
    OUT.mkdir(exist_ok=True)
    out = OUT / "stages_against.json"
    out.write_text(json.dumps(result, indent=2) + "\n")
    for robot in ROBOTS:
        s = result["summary"][robot]["controller"]
        print(f"{robot}: stages this {s['this_us']:.1f} us, {args.against} ({commit}) {s['other_us']:.1f} us, "
              f"ratio x{s['ratio']:.3f} (median of {args.runs} runs)")
    print(f"{out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()

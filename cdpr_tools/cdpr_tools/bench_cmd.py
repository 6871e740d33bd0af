"""``cdpr bench [AREA ...]``: run the benchmarks in benchmarks/bench_<area>.py.

Each benchmark writes bench/<area>.json (figures named with their unit, beside a baseline measured
in the same run). Benchmarks measure; they never fail on a timing.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

BENCH_DIR = Path(__file__).resolve().parents[2] / "benchmarks"


def add_parser(sub) -> None:
    p = sub.add_parser("bench", help="run benchmarks (all, or the named areas) and write bench/*.json")
    p.add_argument("areas", nargs="*", help="areas to run, e.g. model force_distribution")
    p.set_defaults(run=run)


def available() -> list[str]:
    return sorted(p.stem.removeprefix("bench_") for p in BENCH_DIR.glob("bench_*.py"))


def run(args) -> int:
    areas = args.areas or available()
    unknown = sorted(set(areas) - set(available()))
    if unknown:
        raise ValueError(f"unknown benchmark {', '.join(unknown)}; available: {', '.join(available())}")
    failed = []
    for area in areas:
        print(f"== bench {area}", flush=True)
        rc = subprocess.call([sys.executable, str(BENCH_DIR / f"bench_{area}.py")], cwd=BENCH_DIR.parent)
        if rc != 0:
            failed.append(area)
    if failed:
        print(f"benchmarks that crashed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0

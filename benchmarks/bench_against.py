"""The composed graph of this tree against another tree's, both running at the same time.

On this shared two-core machine the speed of a run moves by 10-25 % between runs a minute apart
(docs/performance.md), so two trees measured one after the other differ by the machine as much as
by the code. Here both trees' composed lockstep graphs (graphs/closed_loop.yaml, IPAnema 3 Mini
holding home, the default plant) run *at the same time*, each in a process and ROS domain of its
own, each pinned to a core of its own (the cores swap every round): whatever the machine does to
one it does to the other, and the ratio of their figures in a round is the comparison. A tree against itself (the default) gives the instrument's
own spread.

Per tree and round: the real-time factor (simulated over wall time of the window), the process CPU
per period, and the CPU of the executor's thread per period as the median over 50 ms slices of the
window (the slices a burst of other work lands in drop out of a median). Which tree starts first,
and on which core, alternates; a fresh worktree first runs one round that is not counted (numba compiles its kernels
into the tree's cache).

    .venv/bin/python benchmarks/bench_against.py [--against REF] [--rounds N] [--window S] [--record]

With ``--record`` each graph's bag writer (a child process) runs on its graph's core too, where
``make bench`` (graph) lets it use the other core: the ratio compares the trees, the absolute figures
are not those of bench_graph.py.

REF is a git revision (default: ``CDPR_BENCH_AGAINST`` or HEAD), checked out in a temporary
worktree; ``--record`` records every topic in both graphs. Writes bench/against.json
(bench/against_recording.json with ``--record``).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import pathlib
import platform
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "bench"
PACKAGES = ("cdpr_control", "cdpr_sim", "cdpr_tools")

# The child: the tree's own launcher (the API is the same since before the layout of Fig. 3.4).
CHILD = r"""
import json, os, random, statistics, sys, tempfile, threading, time
try:
    from cdpr_tools.file_lock import own_ros_domain
    _domain = own_ros_domain(random.randint(1, 100))
except ImportError:                              # older trees: a domain of its own by chance
    os.environ["ROS_DOMAIN_ID"] = str(random.randint(101, 200))
from cdpr_tools.demo_cmd import GRAPH
from cdpr_tools.launch import Launcher, RecordSpec
from cdpr_tools.launch_file import load_launch_file

warmup, window, record = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3] == "1"
description = load_launch_file(GRAPH, {"robot": "ipanema3_mini", "sync_mode": "exact"})
with tempfile.TemporaryDirectory() as tmp:
    if record:
        description.record = RecordSpec(output=os.path.join(tmp, "bag"))
    with Launcher(description, mode="composed", intra_process=True) as launch:
        sim = next(n for n in launch.nodes if n.get_name() == "winch_platform_sim")
        time.sleep(warmup)
        thread = next(t for t in threading.enumerate() if t.name == "cdpr-launch-graph")
        clock = time.pthread_getcpuclockid(thread.ident)
        s0, t0, c0 = sim.sim.steps, time.perf_counter(), time.process_time()
        slices, last = [], (s0, time.clock_gettime_ns(clock))
        while time.perf_counter() < t0 + window:
            time.sleep(0.05)
            now = sim.sim.steps, time.clock_gettime_ns(clock)
            if now[0] > last[0]:
                slices.append((now[1] - last[1]) / (now[0] - last[0]) * 1e-3)
            last = now
        s1, t1, c1 = sim.sim.steps, time.perf_counter(), time.process_time()
print(json.dumps({"rtf": (s1 - s0) * 1e-3 / (t1 - t0), "periods": s1 - s0,
                  "cpu_us_per_period": (c1 - c0) / max(s1 - s0, 1) * 1e6,
                  "loop_thread_us_per_period": statistics.median(slices) if slices else None}))
"""


@contextlib.contextmanager
def checked_out(ref: str):
    """The git revision ``ref`` in a temporary worktree: (its path, its short commit), removed after."""
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", ref], check=True,
                            capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="bench_against_") as tmp:
        path = pathlib.Path(tmp) / "other"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(path), ref],
                       check=True, capture_output=True, text=True)
        try:
            yield path, commit
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(path)], capture_output=True)


def start(tree: pathlib.Path, warmup: float, window: float, record: bool, cpu: int | None) -> subprocess.Popen:
    """The child graph of ``tree``, its threads pinned to core ``cpu`` (None: anywhere)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(str(tree / p) for p in PACKAGES)}
    pin = None if cpu is None else (lambda: os.sched_setaffinity(0, {cpu}))
    return subprocess.Popen([sys.executable, "-c", CHILD, str(warmup), str(window), "1" if record else "0"],
                            cwd=tree, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=pin)


def finish(process: subprocess.Popen, tree: pathlib.Path, timeout: float) -> dict:
    out, err = process.communicate(timeout=timeout)
    if process.returncode != 0 or not out.strip():
        raise RuntimeError(f"the graph of {tree} failed (exit {process.returncode}):\n{err[-3000:]}")
    return json.loads(out.strip().splitlines()[-1])


def round_pair(trees: dict, warmup: float, window: float, record: bool, first: str) -> dict:
    """Both graphs at once; ``first`` starts first and, on a machine of two or more cores, runs on core 0
    and the other on core 1 (a core each, so that neither's threads wait for the other's)."""
    order = [first] + [name for name in trees if name != first]
    cores = sorted(os.sched_getaffinity(0))
    processes = {}
    for k, name in enumerate(order):
        processes[name] = start(trees[name], warmup, window, record, cores[k] if len(cores) >= 2 else None)
    timeout = warmup + window + 180.0
    return {name: finish(processes[name], trees[name], timeout) for name in order}


def ratios(rounds: list[dict], key: str) -> list[float]:
    """this tree's figure over the other's, per round (RTF: above 1 is faster; CPU: below 1 is cheaper)."""
    return [r["this"][key] / r["other"][key] for r in rounds if r["this"][key] and r["other"][key]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", default=os.environ.get("CDPR_BENCH_AGAINST", "HEAD"),
                        help="git revision of the other tree (default: CDPR_BENCH_AGAINST or HEAD)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--window", type=float, default=20.0, help="measured seconds of wall time per round")
    parser.add_argument("--warmup", type=float, default=5.0)
    parser.add_argument("--record", action="store_true", help="both graphs record every topic")
    args = parser.parse_args()
    with checked_out(args.against) as (other, commit):
        trees = {"this": ROOT, "other": other}
        print("warm-up round (numba compiles into the trees' caches) ...", flush=True)
        round_pair(trees, args.warmup, 5.0, args.record, "other")
        rounds = []
        for k in range(args.rounds):
            rounds.append(round_pair(trees, args.warmup, args.window, args.record, ["this", "other"][k % 2]))
            r = rounds[-1]
            print(f"round {k + 1}: RTF this {r['this']['rtf']:.3f} other {r['other']['rtf']:.3f}; loop thread "
                  f"us/period this {r['this']['loop_thread_us_per_period']:.0f} "
                  f"other {r['other']['loop_thread_us_per_period']:.0f}", flush=True)
    rtf, cpu = ratios(rounds, "rtf"), ratios(rounds, "loop_thread_us_per_period")
    result = {
        "machine": platform.machine(), "cpu_count": os.cpu_count(), "against": args.against, "against_commit": commit,
        "graph": "graphs/closed_loop.yaml, ipanema3_mini holding home, default plant, composed lockstep"
                 + (", recording every topic" if args.record else ""),
        "window_s": args.window, "rounds": rounds,
        "rtf_ratio": rtf, "rtf_ratio_median": statistics.median(rtf),
        "loop_thread_cpu_ratio": cpu, "loop_thread_cpu_ratio_median": statistics.median(cpu),
    }
    OUT.mkdir(exist_ok=True)
    out = OUT / ("against_recording.json" if args.record else "against.json")
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"this tree against {args.against} ({commit}): RTF x{result['rtf_ratio_median']:.3f}, "
          f"loop thread CPU per period x{result['loop_thread_cpu_ratio_median']:.3f} (medians of {len(rounds)} "
          f"rounds); {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()

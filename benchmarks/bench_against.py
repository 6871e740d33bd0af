"""The composed graph of this tree against another tree's, taking turns on one core.

On this shared two-core machine the speed of a run moves by 10-25 % between runs a minute apart,
and the two cores' speeds move apart by up to 50 % within a minute (docs/performance.md), so two
trees measured one after the other, or at the same time on a core each, differ by the machine as
much as by the code. Here both trees' composed lockstep graphs (graphs/closed_loop.yaml, IPAnema 3
Mini holding home, the default plant) run in a process and ROS domain of their own, both pinned to
*one* core, and take turns: one runs for ``--turn`` seconds while the other is stopped (SIGSTOP to
its process group), then the other. Each pair of neighbouring turns gives a ratio; the pair's order
alternates (ABBA), so a steady drift cancels.

- Turns are short (0.25 s) because the core's speed moves within seconds: the loop thread's CPU
  time per period of one tree went from 1264 to 1872 us between its neighbouring 2 s turns (session 23).
- Two processes of the same code differ by a few per cent (memory layout), so a round is a fresh
  pair of processes, which one starts first and the core alternate between rounds, and the
  interval resamples whole rounds.
- A tree against itself (the default) gives the instrument's own spread.

Per tree and turn: the real-time factor (simulated over wall time of the turn, its first
``SETTLE_S`` left out) and the CPU time of the executor's thread per period. A child reports ready
once its simulator has stepped 200 periods: a fresh worktree compiles its kernels in the first
ones (into its cache, so only the first round waits for that).

    .venv/bin/python benchmarks/bench_against.py [--against REF] [--rounds N] [--turns N] [--turn S] [--record] [--deliveries]

With ``--deliveries`` each child also times every in-process delivery (a clock around each local
subscription's callback), and the summary gives per node the us per period of both trees
in the same turns: which node's period grew, where the ratio alone says only that something did
(session 24 found the period's IK of x_d computed three times a period with it).

With ``--record`` each graph's bag writer (a child process) runs on the same core and stops with
its graph: the ratio compares the trees, the absolute figures are not those of bench_graph.py.

REF is a git revision (default: ``CDPR_BENCH_AGAINST`` or HEAD), checked out in a temporary
worktree. Writes bench/against.json (bench/against_recording.json with ``--record``).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import pathlib
import platform
import random
import select
import signal
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "bench"
PACKAGES = ("cdpr_control", "cdpr_sim", "cdpr_tools")
SAMPLE_S = 0.05     # the child's sampling period [s] (a turn of 0.25 s holds about five samples)
SETTLE_S = 0.03     # the start of a turn left out [s]: the graph resumes where it stopped
START_S = 600.0     # longest wait for a child's graph to start [s] (a fresh tree compiles its kernels)

# The child: the tree's own launcher (the API is the same since before the layout of Fig. 3.4). It
# says it is ready once its simulator stepped 200 periods (a fresh tree's kernels compile in the first
# ones), then samples (time, simulator steps, CPU time of the graph's thread) until its stdin gives a line;
# while it is stopped it takes no sample, and the parent's turns say which samples count.
CHILD = r"""
import json, os, random, sys, tempfile, threading, time
try:
    from cdpr_tools.file_lock import own_ros_domain
    _domain = own_ros_domain(random.randint(1, 100))
except ImportError:                              # older trees: a domain of its own by chance
    os.environ["ROS_DOMAIN_ID"] = str(random.randint(101, 200))
from cdpr_tools.demo_cmd import GRAPH
from cdpr_tools.launch import Launcher, RecordSpec
from cdpr_tools.launch_file import load_launch_file

# Time every in-process delivery: totals[subscriber node <- topic] = [ns, deliveries]. Each local
# subscription's callback is wrapped in a clock as it registers (the registry and its LocalSubscription
# are the same since 784c4eb); taps, called inside publish, count in their publisher's delivery. A
# delivery longer than LONG_NS is left out (a SIGSTOP fell into it).
def time_deliveries(totals):
    import importlib
    for name in ("cdpr_control.ros.intraprocess", "cdpr_control.nodes.intraprocess"):
        try:
            ip = importlib.import_module(name)
            break
        except ImportError:
            pass
    add, clock, LONG_NS = ip.IntraProcess.add_subscription, time.perf_counter_ns, 5_000_000

    def timed(callback, label):
        def call(msg):
            t0 = clock()
            callback(msg)
            dt = clock() - t0
            if dt < LONG_NS:
                entry = totals.get(label)
                if entry is None:
                    totals[label] = [dt, 1]
                else:
                    entry[0] += dt
                    entry[1] += 1
        return call

    def add_subscription(self, local):
        if not local.tap:
            local.callback = timed(local.callback, f"{local.node.get_name()} <- {local.topic.name}")
        add(self, local)

    ip.IntraProcess.add_subscription = add_subscription


record, sample, per_delivery = sys.argv[1] == "1", float(sys.argv[2]), sys.argv[3] == "1"
totals = {}
if per_delivery:
    time_deliveries(totals)
description = load_launch_file(GRAPH, {"robot": "ipanema3_mini", "sync_mode": "exact"})
stop = threading.Event()
threading.Thread(target=lambda: (sys.stdin.readline(), stop.set()), daemon=True).start()
samples = []
with tempfile.TemporaryDirectory() as tmp:
    if record:
        description.record = RecordSpec(output=os.path.join(tmp, "bag"))
    with Launcher(description, mode="composed", intra_process=True) as launch:
        sim = next(n for n in launch.nodes if n.get_name() == "winch_platform_sim")
        thread = next(t for t in threading.enumerate() if t.name == "cdpr-launch-graph")
        clock = time.pthread_getcpuclockid(thread.ident)
        while sim.sim.steps < 200:           # running (a fresh tree compiles its kernels in the first periods)
            time.sleep(sample)
        print("ready", flush=True)
        while not stop.wait(sample):
            samples.append((time.perf_counter(), sim.sim.steps, time.clock_gettime_ns(clock))
                           + (({k: tuple(v) for k, v in totals.items()},) if per_delivery else ()))
print(json.dumps(samples))
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


class Graph:
    """One tree's composed graph in a child process of its own group, pinned to core ``cpu``."""

    def __init__(self, tree: pathlib.Path, record: bool, cpu: int, per_delivery: bool = False):
        self.tree = tree
        self.errors = tempfile.TemporaryFile(mode="w+")    # not a pipe: a full pipe would block the graph
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(str(tree / p) for p in PACKAGES)}
        self.process = subprocess.Popen(
            [sys.executable, "-c", CHILD, "1" if record else "0", str(SAMPLE_S), "1" if per_delivery else "0"], cwd=tree, env=env,
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.errors, text=True,
            start_new_session=True,         # its own process group: SIGSTOP reaches its bag writer too
            preexec_fn=lambda: os.sched_setaffinity(0, {cpu}))

    def ready(self) -> None:
        readable, _, _ = select.select([self.process.stdout], [], [], START_S)
        if not readable or self.process.stdout.readline().strip() != "ready":
            self.failed("did not start")

    def signal(self, number: int) -> None:
        os.killpg(self.process.pid, number)

    def samples(self) -> list:
        self.signal(signal.SIGCONT)
        out, _ = self.process.communicate("stop\n", timeout=180.0)
        if self.process.returncode != 0 or not out.strip():
            self.failed(f"exited {self.process.returncode}")
        return json.loads(out.strip().splitlines()[-1])

    def kill(self) -> None:
        """The whole group (a stopped bag writer left behind would stay stopped for good)."""
        with contextlib.suppress(ProcessLookupError):
            self.signal(signal.SIGKILL)
        self.process.wait()

    def failed(self, what: str):
        self.kill()
        self.errors.seek(0)
        raise RuntimeError(f"the graph of {self.tree} {what}:\n{self.errors.read()[-3000:]}")


def turn_figures(samples: list, t0: float, t1: float) -> dict | None:
    """RTF and loop-thread CPU per period over the samples of one turn [t0, t1], its start left out."""
    inside = [s for s in samples if t0 + SETTLE_S <= s[0] <= t1]
    if len(inside) < 2 or inside[-1][1] <= inside[0][1]:
        return None
    (ta, sa, ca, *da), (tb, sb, cb, *db) = inside[0], inside[-1]
    figures = {"rtf": (sb - sa) * 1e-3 / (tb - ta), "loop_thread_us_per_period": (cb - ca) / (sb - sa) * 1e-3}
    if db:          # --deliveries: each subscriber's in-process deliveries, us per period
        before = da[0]
        figures["deliveries_us_per_period"] = {
            label: (ns - before.get(label, (0, 0))[0]) / (sb - sa) * 1e-3 for label, (ns, _) in db[0].items()}
    return figures


def run_round(trees: dict, record: bool, cpu: int, turns: int, turn: float, warmup: float, first: str,
              per_delivery: bool = False) -> dict:
    """Both graphs pinned to core ``cpu`` (``first`` started first): after ``warmup`` s together,
    ``turns`` pairs of turns of ``turn`` s each, the pair's order alternating (ABBA). Per pair: each
    tree's figures and the ratio."""
    order = [first] + [name for name in trees if name != first]
    graphs = {name: Graph(trees[name], record, cpu, per_delivery) for name in order}
    try:
        for graph in graphs.values():
            graph.ready()
        time.sleep(warmup)
        for graph in graphs.values():
            graph.signal(signal.SIGSTOP)
        spans = []
        for k in range(turns):
            pair = ("this", "other") if k % 2 == 0 else ("other", "this")
            for name in pair:
                graphs[name].signal(signal.SIGCONT)
                t0 = time.perf_counter()
                time.sleep(turn)
                graphs[name].signal(signal.SIGSTOP)
                spans.append((k, name, t0, time.perf_counter()))
        samples = {name: graph.samples() for name, graph in graphs.items()}
    except BaseException:
        for graph in graphs.values():
            graph.kill()
        raise
    pairs = [{} for _ in range(turns)]
    for k, name, t0, t1 in spans:
        pairs[k][name] = turn_figures(samples[name], t0, t1)
    pairs = [p for p in pairs if p["this"] and p["other"]]
    if not pairs:
        raise RuntimeError(f"no turn in which both graphs stepped (core {cpu}): is a graph stuck?")
    return {"cpu": cpu, "first": first, "pairs": pairs, "rtf_ratio": ratios(pairs, "rtf"),
            "loop_thread_cpu_ratio": ratios(pairs, "loop_thread_us_per_period")}


def ratios(pairs: list[dict], key: str) -> list[float]:
    """this tree's figure over the other's, per pair of turns (RTF: above 1 is faster; CPU: below 1 is cheaper)."""
    return [p["this"][key] / p["other"][key] for p in pairs]


def delivery_table(rounds: list[dict], by_node: bool = True) -> list[dict]:
    """Per subscribing node (``by_node``; else per node and topic) with --deliveries: the median over
    all pairs of turns of each tree's us per period and of their difference (this - other), largest
    difference first. A node computes its period in the delivery that completes its inputs, which
    may be another topic in the other tree: compare nodes, not topics. "(outside the deliveries)"
    is the loop thread's CPU per period less the deliveries' sum: the executor, timers, the lockstep
    runner, the clock's fan-out (CPU time against the deliveries' wall time: near, not equal)."""
    outside = "(outside the deliveries)"
    rows = {}
    for r in rounds:
        for pair in r["pairs"]:
            figures = {}
            for name in ("this", "other"):
                d = {}
                for label, us in pair[name]["deliveries_us_per_period"].items():
                    key = label.split(" <- ")[0] if by_node else label
                    d[key] = d.get(key, 0.0) + us
                d[outside] = pair[name]["loop_thread_us_per_period"] - sum(d.values())
                figures[name] = d
            for label in figures["this"].keys() | figures["other"].keys():
                a, b = figures["this"].get(label, 0.0), figures["other"].get(label, 0.0)
                rows.setdefault(label, []).append((a, b, a - b))
    table = [{"delivery": label, "this_us": statistics.median(x[0] for x in v),
              "other_us": statistics.median(x[1] for x in v), "difference_us": statistics.median(x[2] for x in v)}
             for label, v in rows.items()]
    return sorted(table, key=lambda row: -abs(row["difference_us"]))


def interval(rounds: list[list[float]], level: float = 0.95, resamples: int = 4000) -> tuple[float, float]:
    """Bootstrap interval of the median ratio, resampling whole rounds (the pairs of one round share
    its two processes, whose memory layouts differ by a few per cent: they are not independent).
    A fixed seed: the same figures give the same interval."""
    rng = random.Random(0)
    medians = sorted(statistics.median([x for r in rng.choices(rounds, k=len(rounds)) for x in r])
                     for _ in range(resamples))
    tail = int(resamples * (1.0 - level) / 2.0)
    return medians[tail], medians[-tail - 1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", default=os.environ.get("CDPR_BENCH_AGAINST", "HEAD"),
                        help="git revision of the other tree (default: CDPR_BENCH_AGAINST or HEAD)")
    parser.add_argument("--rounds", type=int, default=8, help="rounds (each a fresh pair of graphs; the core alternates)")
    parser.add_argument("--turns", type=int, default=24, help="pairs of turns per round")
    parser.add_argument("--turn", type=float, default=0.25, help="wall time of one turn [s]")
    parser.add_argument("--warmup", type=float, default=3.0, help="both graphs running before the turns [s]")
    parser.add_argument("--record", action="store_true", help="both graphs record every topic")
    parser.add_argument("--deliveries", action="store_true",
                        help="also time each subscriber's in-process deliveries (what differs, node by node)")
    args = parser.parse_args()
    cores = sorted(os.sched_getaffinity(0))
    with checked_out(args.against) as (other, commit):
        trees = {"this": ROOT, "other": other}
        rounds = []
        for k in range(args.rounds):
            cpu = cores[k % len(cores)]
            rounds.append(run_round(trees, args.record, cpu, args.turns, args.turn, args.warmup,
                                    ("this", "this", "other", "other")[k % 4], args.deliveries))
            r = rounds[-1]
            print(f"round {k + 1} (core {cpu}, {r['first']} first): RTF ratio median {statistics.median(r['rtf_ratio']):.3f} "
                  f"({len(r['pairs'])} pairs, {min(r['rtf_ratio']):.3f}..{max(r['rtf_ratio']):.3f}); loop thread "
                  f"CPU ratio median {statistics.median(r['loop_thread_cpu_ratio']):.3f}", flush=True)
    rtf = [x for r in rounds for x in r["rtf_ratio"]]
    cpu = [x for r in rounds for x in r["loop_thread_cpu_ratio"]]
    rtf_rounds, cpu_rounds = [r["rtf_ratio"] for r in rounds], [r["loop_thread_cpu_ratio"] for r in rounds]
    result = {
        "machine": platform.machine(), "cpu_count": os.cpu_count(), "against": args.against, "against_commit": commit,
        "graph": "graphs/closed_loop.yaml, ipanema3_mini holding home, default plant, composed lockstep"
                 + (", recording every topic" if args.record else ""),
        "turn_s": args.turn, "turns": args.turns, "rounds": rounds,
        "rtf_ratio_median": statistics.median(rtf), "rtf_ratio_interval_95": interval(rtf_rounds),
        "loop_thread_cpu_ratio_median": statistics.median(cpu), "loop_thread_cpu_ratio_interval_95": interval(cpu_rounds),
    }
    if args.deliveries:
        result["deliveries"] = delivery_table(rounds, by_node=False)
        result["nodes"] = delivery_table(rounds)
        print(f"{'us per period (medians over the pairs)':60s} {'this':>8s} {'other':>8s} {'this-other':>10s}")
        for row in result["nodes"]:
            print(f"{row['delivery'][:60]:60s} {row['this_us']:8.1f} {row['other_us']:8.1f} {row['difference_us']:+10.1f}")
    OUT.mkdir(exist_ok=True)
    out = OUT / ("against_recording.json" if args.record else "against.json")
    out.write_text(json.dumps(result, indent=2) + "\n")
    lo, hi = result["rtf_ratio_interval_95"]
    print(f"this tree against {args.against} ({commit}): RTF x{result['rtf_ratio_median']:.3f} "
          f"(95 % interval {lo:.3f}..{hi:.3f}; {len(rtf)} pairs of turns in {len(rounds)} rounds), loop thread CPU per "
          f"period x{result['loop_thread_cpu_ratio_median']:.3f}; {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()

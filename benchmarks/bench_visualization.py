"""What the visualization node costs the 1 kHz loop: the composed graph with and without it.

The IPAnema 3 Mini holds still at home in lockstep (graphs/closed_loop.yaml, composed, nominal
simulator plant), measured as in bench_graph.py (simulated over wall time in a window after a
warm-up, the simulated time read from the simulator node in the process), alternating without/with
the visualization node, twice each, in the same run. Figures: real-time factor and wall time per
period of each configuration (the baseline is the graph without the node), the ratio, and the CPU
time of the node's own callbacks (its marker timer and input subscriptions, thread CPU time) per
control period, taken in a second window with the callbacks timed (timing them costs the loop
itself, so the first window's RTF is untimed). The node samples its inputs (no callback per message), so
the loop's only extra work is handing each of four topics to one more reader.

Writes bench/visualization.json. Run: .venv/bin/python benchmarks/bench_visualization.py
"""
from __future__ import annotations

import json
import os
import pathlib
import platform
import random
import statistics
import sys
import time

from cdpr_tools.file_lock import own_ros_domain  # noqa: E402
_DOMAIN_LOCK = own_ros_domain(random.randint(1, 100))   # held for the process: test sessions skip it
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

from bench_graph import (NODE_WINDOW_S, PERIOD_S, ROBOT, START_TIMEOUT_S, CallbackCpu,  # noqa: E402
                         ClockProbe, sim_node)
from cdpr_control.ros.intraprocess import IntraProcess  # noqa: E402
from cdpr_tools.launch import Launcher  # noqa: E402
from cdpr_tools.launch_file import load_launch_file  # noqa: E402
from cdpr_tools.share import package_share  # noqa: E402
from timing import python_calibration_us  # noqa: E402

WARMUP_S = 4.0
WINDOW_S = 10.0
REPEATS = 2
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "visualization.json"


def measure(with_visualization: bool) -> dict:
    description = load_launch_file(package_share("cdpr_tools") / "graphs" / "closed_loop.yaml", {"robot": ROBOT})
    if not with_visualization:
        description.nodes = [n for n in description.nodes if not n.module.endswith(".visualization")]
    probe = ClockProbe(clock=False)     # a /clock reader in another context would cost the simulator DDS
    with Launcher(description, mode="composed") as launch:
        probe.sim = sim_node(launch)
        probe.wait_running(START_TIMEOUT_S)
        time.sleep(WARMUP_S)
        wall0, sim0 = probe.latest
        time.sleep(WINDOW_S)
        wall1, sim1 = probe.latest
        callbacks = CallbackCpu(launch.nodes, IntraProcess.of(launch.nodes[0].context))
        node_sim0 = probe.latest[1]
        time.sleep(NODE_WINDOW_S)
        node_periods = round((probe.latest[1] - node_sim0) * 1e-9 / PERIOD_S)
        node_ns = dict(callbacks.ns)
        errors = list(launch.errors)
    probe.close()
    if errors:
        raise RuntimeError(f"the graph reported errors: {errors}")
    periods = round((sim1 - sim0) * 1e-9 / PERIOD_S)
    wall = wall1 - wall0
    return {"rtf": periods * PERIOD_S / wall, "us_per_period": wall * 1e6 / periods, "periods": periods,
            "visualization_cpu_us_per_period": node_ns.get("visualization", 0.0) * 1e-3 / max(1, node_periods)}


def main() -> None:
    runs = {"without": [], "with": []}
    for _ in range(REPEATS):
        for key in ("without", "with"):
            runs[key].append(measure(key == "with"))
            print(key, json.dumps(runs[key][-1]), flush=True)
    med = {k: {f: statistics.median(r[f] for r in v) for f in v[0]} for k, v in runs.items()}
    result = {
        "robot": ROBOT, "mode": "composed, lockstep, holding home", "plant": "nominal (robot file)",
        "window_s": WINDOW_S, "repeats": REPEATS,
        "baseline_without_visualization": med["without"],
        "with_visualization": med["with"],
        "rtf_ratio_with_over_without": med["with"]["rtf"] / med["without"]["rtf"],
        "visualization_cpu_us_per_period": med["with"]["visualization_cpu_us_per_period"],
        "visualization_share_of_period_pct": 100 * med["with"]["visualization_cpu_us_per_period"] / med["with"]["us_per_period"],
        "runs": runs,
        "python_calibration_us": python_calibration_us(),
        "loadavg_1min": os.getloadavg()[0],
        "machine": platform.platform(),
    }
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: result[k] for k in ("rtf_ratio_with_over_without", "visualization_cpu_us_per_period",
                                             "visualization_share_of_period_pct")}, indent=2))


if __name__ == "__main__":
    main()

"""What `cdpr view` costs the 1 kHz loop: unwatched nothing, watched one topic a little.

The IPAnema 3 Mini holds still at home in lockstep (graphs/closed_loop.yaml, composed, the default
mismatched simulator plant, as `cdpr launch` runs it), measured as in bench_graph.py (simulated
over wall time in a window after a warm-up, the simulated time read from the simulator node in the
process). Three configurations, alternated, REPEATS times each, in the same run:

- ``without``: the graph alone (the baseline);
- ``view_unwatched``: `cdpr view` running in a process of its own, no Foxglove client connected;
- ``view_cable_forces``: the same with a WebSocket client (the Foxglove protocol) subscribed to
  /cable_forces only, receiving every message.

Targets (issue 27): unwatched within 5 % of the baseline's RTF, one topic watched within 10 %.
Writes bench/view.json. Run: .venv/bin/python benchmarks/bench_view.py
"""
from __future__ import annotations

import json
import os
import pathlib
import platform
import random
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time

os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

from bench_graph import PERIOD_S, ROBOT, START_TIMEOUT_S, ClockProbe, sim_node  # noqa: E402
from cdpr_tools.launch import Launcher  # noqa: E402
from cdpr_tools.launch_file import load_launch_file  # noqa: E402
from cdpr_tools.share import package_share  # noqa: E402
from websockets.sync.client import connect  # noqa: E402

WARMUP_S = 4.0
WINDOW_S = 10.0
REPEATS = 2
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
TARGETS = {"unwatched_rtf_ratio_min": 0.95, "one_topic_rtf_ratio_min": 0.90}
OUT = pathlib.Path(__file__).resolve().parents[1] / "bench" / "view.json"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Watcher:
    """A Foxglove WebSocket client subscribed to one topic, counting what it receives."""

    def __init__(self, port: int, topic: str):
        deadline = time.monotonic() + 60
        while True:                    # the view process listens once it has started
            try:
                self.ws = connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, open_timeout=30)
                break
            except ConnectionRefusedError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        self.received, self._stop = 0, threading.Event()
        while True:
            data = self.ws.recv(timeout=max(0.1, deadline - time.monotonic()))
            if isinstance(data, str) and json.loads(data)["op"] == "advertise":
                channels = {c["topic"]: c["id"] for c in json.loads(data)["channels"]}
                if topic in channels:
                    break
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channels[topic]}]}))
        self.thread = threading.Thread(target=self._receive, daemon=True)
        self.thread.start()

    def _receive(self) -> None:
        while not self._stop.is_set():
            try:
                if isinstance(self.ws.recv(timeout=0.2), bytes):
                    self.received += 1
            except TimeoutError:
                continue
            except Exception:
                return

    def close(self) -> None:
        self._stop.set()
        self.thread.join(5)
        self.ws.close()


def measure(config: str) -> dict:
    description = load_launch_file(package_share("cdpr_tools") / "graphs" / "closed_loop.yaml", {"robot": ROBOT})
    probe = ClockProbe(clock=False)
    view = watcher = None
    with Launcher(description, mode="composed") as launch:
        probe.sim = sim_node(launch)
        probe.wait_running(START_TIMEOUT_S)
        if config != "without":
            port = free_port()
            view = subprocess.Popen([sys.executable, "-m", "cdpr_tools.cli", "view", "--port", str(port)],
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            if config == "view_cable_forces":
                watcher = Watcher(port, "/cable_forces")
        try:
            time.sleep(WARMUP_S)
            wall0, sim0 = probe.latest
            received0 = watcher.received if watcher else 0
            time.sleep(WINDOW_S)
            wall1, sim1 = probe.latest
            received = (watcher.received if watcher else 0) - received0
            errors = list(launch.errors)
        finally:
            if watcher is not None:
                watcher.close()
            if view is not None:
                view.send_signal(signal.SIGINT)
                view.wait(30)
    probe.close()
    if errors:
        raise RuntimeError(f"the graph reported errors: {errors}")
    periods = round((sim1 - sim0) * 1e-9 / PERIOD_S)
    return {"rtf": periods * PERIOD_S / (wall1 - wall0), "periods": periods,
            "cable_forces_received_per_period": received / max(1, periods)}


def main() -> None:
    configs = ("without", "view_unwatched", "view_cable_forces")
    runs = {c: [] for c in configs}
    for _ in range(REPEATS):
        for config in configs:
            runs[config].append(measure(config))
            print(config, json.dumps(runs[config][-1]), flush=True)
    med = {c: statistics.median(r["rtf"] for r in runs[c]) for c in configs}
    result = {
        "robot": ROBOT, "mode": "composed, lockstep, holding home",
        "plant": "winch_platform_sim as graphs/closed_loop.yaml configures it (default mismatched plant)",
        "window_s": WINDOW_S, "repeats": REPEATS, "rtf_median": med,
        "unwatched_rtf_ratio": med["view_unwatched"] / med["without"],
        "one_topic_rtf_ratio": med["view_cable_forces"] / med["without"],
        "targets": TARGETS, "runs": runs, "loadavg_1min": os.getloadavg()[0], "machine": platform.platform(),
    }
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: result[k] for k in ("rtf_median", "unwatched_rtf_ratio", "one_topic_rtf_ratio")}, indent=2))


if __name__ == "__main__":
    main()

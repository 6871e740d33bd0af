"""A cut DDS link (issue 18): the simulator on host A and the controllers on host B (two network
namespaces joined by a veth pair, as in test_graph_distributed.py), lockstep; the link goes down
for 3 s while the loop runs, then up again.

While cut, the simulator holds the last command (the cables stay tensed) and advances only on its
lockstep timeout, naming each missed deadline on /diagnostics; nothing reaches the drives but
finite commands without a step; when the link is back the loop closes again by itself.
Skipped, saying why, where the machine does not allow network namespaces.
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from cdpr_control.model.robot import load_robot
from test_graph_distributed import split_over_hosts, stop, two_hosts  # noqa: F401 (fixture)

CUT_S = 3.0           # s the link is down
PERIODS = 100         # periods answered before the cut, and again after it
TIMEOUT_S = 150.0     # wall time for start-up, discovery and both phases
PERIOD_NS = 1_000_000
# In host A's namespace: counts answered periods, cuts the link (ip link set DEV down), restores it,
# waits for the loop to close again; prints the stamps, the commands and the simulator's statuses.
PROBE = r"""
import json, subprocess, sys, threading, time
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from cdpr_control.ros.qos import CONTROL, DIAGNOSTICS
from cdpr_control.ros.runner import spin
from cdpr_tools.ros_graph import new_context

timeout, periods, cut_s, dev = float(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
context = new_context()
node = Node("cut_link_probe", context=context, start_parameter_services=False)
states, commands, statuses = set(), [], []
stamp = lambda m: m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
node.create_subscription(JointState, "/winch/state", lambda m: states.add(stamp(m)), CONTROL)
# (with the message info: when host B wrote the command and when host A's DDS took it in, system
# time of the one machine; the executor (SingleThreaded: the events executor passes no info) may run
# the callback much later on a loaded machine)
node.create_subscription(JointState, "/winch/command", lambda m, info: commands.append(
    (stamp(m), list(m.position), info["source_timestamp"], info["received_timestamp"])), CONTROL)
node.create_subscription(DiagnosticArray, "/diagnostics", lambda a: statuses.extend(
    (time.monotonic(), s.name, s.message) for s in a.status), DIAGNOSTICS)
executor = SingleThreadedExecutor(context=context)
executor.add_node(node)
stop = threading.Event()
threading.Thread(target=spin, args=(executor, stop), daemon=True).start()
answered = lambda: len(states & {c[0] for c in commands})
deadline = time.monotonic() + timeout
while time.monotonic() < deadline and answered() < periods:
    time.sleep(0.05)
before = answered()
cut = time.monotonic()
subprocess.run(["ip", "link", "set", dev, "down"], check=True)
down_ns = time.time_ns()            # the link is down: nothing written from now on crosses ...
time.sleep(cut_s)
up_ns = time.time_ns()              # ... until it is up again
subprocess.run(["ip", "link", "set", dev, "up"], check=True)
restored = time.monotonic()
while time.monotonic() < deadline and answered() < before + periods:
    time.sleep(0.05)
stop.set()
time.sleep(0.3)
print(json.dumps({"before": before, "after": answered(), "commands": commands, "cut": cut, "restored": restored,
                  "down_ns": down_ns, "up_ns": up_ns,
                  "statuses": statuses}), flush=True)
"""


def test_cut_link_between_simulator_and_controllers(two_hosts):
    host_a = two_hosts[0][0]
    dev = subprocess.run(["ip", "-n", host_a, "-o", "link", "show", "type", "veth"], capture_output=True,
                         text=True, check=True).stdout.split(":")[1].strip().split("@")[0]
    sim, controllers, in_a, env_a = split_over_hosts(two_hosts)
    try:
        done = subprocess.run([*in_a, sys.executable, "-c", PROBE, str(TIMEOUT_S), str(PERIODS), str(CUT_S), dev],
                              env=env_a, capture_output=True, text=True, timeout=TIMEOUT_S + 60)
    finally:
        log = stop(sim, controllers)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["before"] >= PERIODS, f"the loop did not close before the cut; launch output:\n{log[-3000:]}"
    # the graph is usable again: the loop closed by itself after the link came back
    assert result["after"] >= result["before"] + PERIODS, f"the loop did not close again:\n{log[-3000:]}"
    # the fault is named: the simulator reports the periods it advanced without a command
    named = [msg for t, name, msg in result["statuses"]
             if name.endswith("winch_platform_sim") and result["cut"] <= t and "missed deadline" in msg
             and not msg.startswith("lockstep: 0 ")]
    assert named, f"no missed deadline reported during the cut: {result['statuses'][-10:]}"
    # the link was cut: no command written while it was down was taken in before it was up again
    # (judged on DDS's write and reception times, not on when the probe's callback ran: on a loaded
    # machine that came more than 0.5 s after a command already on its way at the cut)
    crossed = [c[:1] + c[2:] for c in result["commands"] if c[2] > result["down_ns"] and c[3] < result["up_ns"]]
    assert not crossed, f"commands crossed the cut link (stamp, written, received): {crossed[:5]}"
    # no NaN and no step reached the drives (the joint command's rate limit per period)
    commands = sorted(result["commands"], key=lambda c: c[0])
    stamps = np.array([c[0] for c in commands])
    q = np.array([c[1] for c in commands])
    robot = load_robot("ipanema3_mini")
    assert q.shape[1] == robot.m and np.all(np.isfinite(q))
    steps = np.abs(np.diff(q, axis=0)).max(axis=1) / np.maximum(np.diff(stamps) / PERIOD_NS, 1.0)
    assert np.all(steps <= robot.drive.v_max * PERIOD_NS * 1e-9 * (1 + 1e-9) + 1e-12)

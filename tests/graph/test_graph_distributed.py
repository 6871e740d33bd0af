"""The closed loop of graphs/closed_loop.yaml across process and host boundaries.

- A composed graph (in-process delivery) still shows every loop topic to a node in another process.
- The simulator and the controllers in two processes that find each other only through DDS close
  the lockstep loop: every winch state is answered by a winch command with its stamp.
- The same with the two processes in two network namespaces joined by a veth pair (a network of
  two hosts, UDP only), created by the test; skipped where the machine does not allow namespaces.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import uuid

import pytest

from cdpr_tools.demo_cmd import GRAPH

STARTUP_S = 150.0    # wall time for both parts to start, discover each other and answer N periods
PERIODS = 200        # winch states the probe must see answered by winch commands
LOOP_TOPICS = {      # one message per control period each
    "/winch/state": "sensor_msgs/msg/JointState", "/winch/command": "sensor_msgs/msg/JointState",
    "/setpoint": "cdpr_msgs/msg/OperationalSetpoint", "/cable_forces": "cdpr_msgs/msg/CableForces",
    "/platform/pose": "geometry_msgs/msg/PoseStamped", "/platform/wrench": "geometry_msgs/msg/WrenchStamped",
    "/forward_kinematics/diagnostics": "cdpr_msgs/msg/ForwardKinematicsDiagnostics",
    "/force_distribution": "cdpr_msgs/msg/ForceDistribution",
    "/cable_force_controller/state": "cdpr_msgs/msg/ControllerState", "/ospc/state": "cdpr_msgs/msg/ControllerState",
    "/ground_truth/pose": "geometry_msgs/msg/PoseStamped",
}
# A probe in a process of its own: counts the stamps of the loop topics until PERIODS winch states
# were answered (and, with "diagnostics", a simulator report timed a command), then prints a JSON
# summary. argv: timeout [s], periods, topics (JSON name -> type)[, "diagnostics"].
PROBE = r"""
import json, sys, threading, time
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from cdpr_control.ros.qos import CONTROL
from cdpr_control.ros.runner import spin
from cdpr_tools.message_convert import message_class
from cdpr_tools.ros_graph import new_context

timeout, periods, topics = float(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3])
context = new_context()
node = Node("distributed_probe", context=context, start_parameter_services=False)
stamps = {topic: [] for topic in topics}
reports = []    # the simulator's /diagnostics values

def on_diagnostics(m):
    reports.extend(dict({kv.key: kv.value for kv in s.values}, message=s.message)
                   for s in m.status if s.name == "/winch_platform_sim")

def keeper(topic):
    return lambda m: stamps[topic].append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec)

for topic, type_name in topics.items():
    node.create_subscription(message_class(type_name), topic, keeper(topic), CONTROL)
if len(sys.argv) > 4 and sys.argv[4] == "diagnostics":
    from cdpr_control.ros.qos import DIAGNOSTICS
    node.create_subscription(message_class("diagnostic_msgs/msg/DiagnosticArray"), "/diagnostics", on_diagnostics,
                             DIAGNOSTICS)
executor = EventsExecutor(context=context)
executor.add_node(node)
stop = threading.Event()
threading.Thread(target=spin, args=(executor, stop), daemon=True).start()
answered = lambda: set(stamps["/winch/state"]) & set(stamps["/winch/command"])
# with the diagnostics: also until a report (one a second) covers a second in which commands came back
# (the first reports can come before the controllers answer, and 200 periods free-running take 0.2 s)
timed = lambda: len(sys.argv) <= 4 or any(r.get("command_latency_count") not in (None, "", "0") for r in reports)
deadline = time.monotonic() + timeout
while time.monotonic() < deadline and (len(answered()) < periods or not timed()):
    time.sleep(0.05)
stop.set()
time.sleep(0.3)
print(json.dumps({"answered": sorted(answered()), "counts": {t: len(s) for t, s in stamps.items()},
                  "reports": reports}), flush=True)
"""


def python_env(**extra) -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p), "PYTHONUNBUFFERED": "1", **extra}


def launch_part(*select: str, prefix=(), env=None) -> subprocess.Popen:
    """``cdpr launch closed_loop.yaml <select>`` (composed) in a process of its own."""
    cmd = [*prefix, sys.executable, "-c", "import sys; from cdpr_tools.cli import main; sys.exit(main(sys.argv[1:]))",
           "launch", str(GRAPH), *select]
    return subprocess.Popen(cmd, env=env or python_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)


def probe(topics: dict, prefix=(), env=None, diagnostics: bool = False) -> dict:
    """``diagnostics``: also keep the simulator's /diagnostics values (``reports``)."""
    done = subprocess.run([*prefix, sys.executable, "-c", PROBE, str(STARTUP_S), str(PERIODS), json.dumps(topics),
                           *(["diagnostics"] if diagnostics else [])],
                          env=env or python_env(), capture_output=True, text=True, timeout=STARTUP_S + 60)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def stop(*processes: subprocess.Popen) -> str:
    output = []
    for p in processes:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGINT)
    for p in processes:
        try:
            out, _ = p.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            out, _ = p.communicate()
        output.append(out or "")
    return "\n".join(output)


def check_loop_closed(result: dict, log: str) -> None:
    answered = result["answered"]
    assert len(answered) >= PERIODS, f"only {len(answered)} periods answered; launch output:\n{log[-3000:]}"
    # distinct periods answered (lockstep: the simulator advanced because the commands came back)
    assert answered[-1] - answered[0] >= (PERIODS - 1) * 1_000_000


def test_a_node_in_another_process_sees_every_topic_of_a_composed_graph():
    graph = launch_part()
    try:
        result = probe(LOOP_TOPICS)
    finally:
        log = stop(graph)
    check_loop_closed(result, log)
    missing = [t for t, n in result["counts"].items() if n == 0]
    assert not missing, f"no message on {missing} outside the composed graph"


def test_simulator_and_controllers_in_two_processes_close_the_loop_over_dds():
    sim = launch_part("--only", "winch_platform_sim")
    controllers = launch_part("--exclude", "winch_platform_sim")
    try:
        result = probe({t: LOOP_TOPICS[t] for t in ("/winch/state", "/winch/command")})
    finally:
        log = stop(sim, controllers)
    check_loop_closed(result, log)


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


@pytest.fixture
def two_hosts():
    """Two network namespaces joined by a veth pair: (name, address) of each."""
    if shutil.which("ip") is None:
        pytest.skip("iproute2 (ip) is not installed: cannot create network namespaces")
    tag = uuid.uuid4().hex[:6]
    hosts = [(f"cdpr_a_{tag}", "10.231.0.1"), (f"cdpr_b_{tag}", "10.231.0.2")]
    veth = (f"va{tag}", f"vb{tag}")
    made = []
    try:
        for name, _ in hosts:
            _ip("netns", "add", name)
            made.append(name)
        _ip("link", "add", veth[0], "type", "veth", "peer", "name", veth[1])
        for (name, address), dev in zip(hosts, veth):
            _ip("link", "set", dev, "netns", name)
            _ip("-n", name, "addr", "add", f"{address}/24", "dev", dev)
            _ip("-n", name, "link", "set", dev, "up", "multicast", "on")
            _ip("-n", name, "link", "set", "lo", "up")
            _ip("-n", name, "route", "add", "224.0.0.0/4", "dev", dev)  # DDS discovery multicast
    except (subprocess.CalledProcessError, PermissionError) as exc:
        for name in made:
            subprocess.run(["ip", "netns", "del", name], capture_output=True)
        detail = exc.stderr.strip() if isinstance(exc, subprocess.CalledProcessError) else str(exc)
        pytest.skip(f"network namespaces are not permitted here ({detail})")
    yield hosts
    for name in made:
        subprocess.run(["ip", "netns", "del", name], capture_output=True)


def host_env(peer: str) -> dict:
    """The environment of a process on one of the two hosts: UDP over the veth only (no shared
    memory between the "hosts"), discovery beyond localhost, ``peer`` the other host's address."""
    return python_env(ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET", ROS_STATIC_PEERS=peer,
                      FASTDDS_BUILTIN_TRANSPORTS="UDPv4")


def split_over_hosts(two_hosts, *arguments: str):
    """The simulator on host A, the controllers on host B: (sim, controllers, prefix and env on A)."""
    (host_a, address_a), (host_b, address_b) = two_hosts
    in_a, in_b = ("ip", "netns", "exec", host_a), ("ip", "netns", "exec", host_b)
    sim = launch_part(*arguments, "--only", "winch_platform_sim", prefix=in_a, env=host_env(address_b))
    controllers = launch_part(*arguments, "--exclude", "winch_platform_sim", prefix=in_b, env=host_env(address_a))
    return sim, controllers, in_a, host_env(address_b)


def test_simulator_and_controllers_on_two_hosts_joined_by_a_veth_pair(two_hosts):
    sim, controllers, in_a, env_a = split_over_hosts(two_hosts)
    try:
        # the probe on host A sees the commands that crossed from host B
        result = probe({t: LOOP_TOPICS[t] for t in ("/winch/state", "/winch/command")}, prefix=in_a, env=env_a)
    finally:
        log = stop(sim, controllers)
    check_loop_closed(result, log)


def test_free_running_across_two_hosts_reports_its_latency_and_missed_periods(two_hosts):
    """Free-running at wall-clock 1 kHz (sync_mode latest) across the veth pair: winch states are
    answered by commands with their stamps, and the simulator reports on /diagnostics, for each
    second, the latency from a winch state to its command and the periods it missed. (The figures
    themselves depend on the machine's load: bench_graph.py's free_running_two_processes measures them.)"""
    sim, controllers, in_a, env_a = split_over_hosts(two_hosts, "sync_mode:=latest")
    try:
        result = probe({t: LOOP_TOPICS[t] for t in ("/winch/state", "/winch/command")}, prefix=in_a, env=env_a,
                       diagnostics=True)
    finally:
        log = stop(sim, controllers)
    check_loop_closed(result, log)
    timed = [r for r in result["reports"] if r.get("command_latency_count") not in (None, "", "0")]
    assert timed, f"no simulator report with a state -> command latency: {result['reports'][-3:]}"
    assert all(r["message"].startswith("free running") and "missed_deadlines" in r and "overruns" in r
               and float(r["command_latency_p99_us"]) > 0.0 for r in timed)

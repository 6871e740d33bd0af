"""The launcher: launch files, composed and multi-process graphs, clean stop on SIGINT, recording."""
import signal
import subprocess
import sys
import threading

import pytest
import yaml
from std_msgs.msg import Int32

from cdpr_test_nodes.graph import STOPPING, Collector, Spinner, subprocess_env, wait_for
from cdpr_tools.bag import BagReader
from cdpr_tools.launch import LaunchDescription, Launcher, NodeSpec, RecordSpec, node_class, ros_arguments
from cdpr_tools.launch_file import load_launch_file
from cdpr_tools.share import package_share

GRAPH = """
launch:
  - arg: {{name: rate, default: "100.0"}}
  - arg: {{name: ns, default: {ns}}}
  - set_parameter: {{name: use_sim_time, value: false}}
  - node:
      pkg: cdpr_test_nodes
      exec: talker
      name: talker_x
      namespace: $(var ns)
      param:
        - {{name: rate, value: $(var rate)}}
        - {{name: greeting, value: launched}}
        - from: talker_params.yaml
  - node:
      pkg: cdpr_test_nodes
      exec: listener
      namespace: $(var ns)
      on_exit: shutdown
"""


def write_graph(tmp_path, mode: str, ns: str):
    (tmp_path / "talker_params.yaml").write_text(yaml.safe_dump(
        {"/**": {"ros__parameters": {"gains": {"kp": 2.5}}}}))
    path = tmp_path / f"{mode}.yaml"
    path.write_text(GRAPH.format(ns=ns))
    return path


def load_recorded(tmp_path, mode: str, ns: str):
    description = load_launch_file(write_graph(tmp_path, mode, ns))
    description.record = RecordSpec(output=str(tmp_path / f"{mode}_bag"))
    return description


@pytest.fixture
def listen():
    spinner = Spinner()
    yield spinner
    spinner.close()


def check_bag(path, ns: str) -> None:
    bag = BagReader(path)
    assert bag.topics[f"{ns}/chatter"].type == "std_msgs/msg/String"
    assert bag.topics[f"{ns}/heard"].message_count > 0
    heard = [m.msg.data for m in bag.messages([f"{ns}/heard"])]
    assert heard == sorted(heard)


def wait_for_graph_and_recorder(launcher, collector, ns: str) -> None:
    """The recorder subscribed to both topics and matched (DDS) the publisher of each - from then on
    it receives what they publish, however loaded the machine (a fixed count of messages after the
    subscription was not enough: DDS matches a reader asynchronously) - and the graph runs."""
    topics = (f"{ns}/chatter", f"{ns}/heard")
    wait_for(lambda: set(topics) <= set(launcher.recorder.recorded_topics), what="recorder subscribed")
    subscriptions = [launcher.recorder._recording[t] for t in topics]
    wait_for(lambda: all(s.get_publisher_count() > 0 for s in subscriptions), what="recorder matched the publishers")
    start = collector.count(f"{ns}/heard")
    wait_for(lambda: collector.count(f"{ns}/heard") >= start + 5, what=f"talker -> listener -> {ns}/heard")


def test_launch_file_arguments_parameters_and_ros_args(tmp_path, monkeypatch):
    monkeypatch.setenv("CDPR_TEST_FRAME", "tool")
    path = write_graph(tmp_path, "composed", "/a")
    text = path.read_text().replace("{name: greeting, value: launched}",
                                    "{name: greeting, value: launched}\n        - {name: frame, value: $(env CDPR_TEST_FRAME)}")
    text = text.replace("      on_exit: shutdown", "      remap: [{from: heard, to: /elsewhere}]\n      ros_args: --log-level warn")
    path.write_text(text)
    description = load_launch_file(path, {"rate": "42.0"})
    talker, listener = description.nodes
    assert talker.module == "cdpr_test_nodes.talker" and listener.module == "cdpr_test_nodes.listener"
    assert talker.parameters[0] == {"rate": 42.0, "greeting": "launched", "frame": "tool"}  # typed, substituted
    assert talker.parameters[1] == str(tmp_path / "talker_params.yaml")  # relative to the launch file
    assert listener.remappings == {"heard": "/elsewhere"} and listener.namespace == "/a"
    assert listener.ros_args == ["--log-level", "warn"] and not listener.required and not talker.required
    assert description.parameters == {"use_sim_time": False}  # set_parameter: every node
    args = ros_arguments(talker, description.parameters, tmp_path)
    assert args[:5] == ["--ros-args", "-r", "__node:=talker_x", "-r", "__ns:=/a"]
    files = [args[i + 1] for i, a in enumerate(args) if a == "--params-file"]
    assert len(files) == 3 and files[2] == str(tmp_path / "talker_params.yaml")
    assert yaml.safe_load(open(files[0])) == {"/**": {"ros__parameters": {"use_sim_time": False}}}
    assert yaml.safe_load(open(files[1]))["/**"]["ros__parameters"]["rate"] == 42.0
    assert node_class("cdpr_test_nodes.talker").__name__ == "Talker"
    assert load_launch_file(write_graph(tmp_path, "composed", "/a")).nodes[1].required  # on_exit: shutdown


def test_launch_file_nested_parameters_let_and_find_pkg_share(tmp_path):
    from cdpr_tools.share import package_share

    path = tmp_path / "nested.yaml"
    path.write_text("""
launch:
  - let: {name: robot, value: ipanema3_mini}
  - node:
      pkg: cdpr_test_nodes
      exec: talker
      param:
        - {name: gains, param: [{name: kp, value: 2.5}, {name: ki, value: $(var robot)}]}
        - from: $(find-pkg-share cdpr_control)/params/$(var robot).yaml
""")
    (talker,) = load_launch_file(path).nodes
    assert talker.parameters[0] == {"gains": {"kp": 2.5, "ki": "ipanema3_mini"}}
    assert talker.parameters[1] == str(package_share("cdpr_control") / "params" / "ipanema3_mini.yaml")
    assert (package_share("cdpr_control") / "params" / "ipanema3_mini.yaml").is_file()


@pytest.mark.parametrize("given, expected", [({}, ["talker"]), ({"listen": "true"}, ["talker", "listener"]),
                                             ({"listen": "1", "quiet": "True"}, ["listener"])])
def test_if_and_unless_switch_actions(tmp_path, given, expected):
    path = tmp_path / "optional.yaml"
    path.write_text("""
launch:
  - arg: {name: listen, default: "false"}
  - arg: {name: quiet, default: "false"}
  - set_parameter: {name: use_sim_time, value: true, if: $(var quiet)}
  - node: {pkg: cdpr_test_nodes, exec: talker, unless: $(var quiet)}
  - node: {pkg: cdpr_test_nodes, exec: listener, if: $(var listen)}
""")
    description = load_launch_file(path, given)
    assert [n.module.rpartition(".")[2] for n in description.nodes] == expected
    assert description.parameters == ({"use_sim_time": True} if given.get("quiet") else {})
    with pytest.raises(ValueError, match=r"launch\[4\] \(node\): if: 'maybe' is not true, false, 1 or 0"):
        load_launch_file(path, {"listen": "maybe"})


def test_cdpr_launch_finds_a_file_in_a_package_share_and_shows_it():
    run = subprocess.run([sys.executable, "-m", "cdpr_tools.cli", "launch", "cdpr_tools", "closed_loop.yaml",
                          "robot:=ipanema3", "--show"], capture_output=True, text=True, env=subprocess_env(), timeout=60)
    assert run.returncode == 0, run.stderr
    shown = yaml.safe_load(run.stdout)
    assert shown["mode"] == "composed" and shown["parameters"] == {"use_sim_time": True, "sync_mode": "exact"}
    modules = [n["module"] for n in shown["nodes"]]
    assert modules[0] == "cdpr_sim.nodes.winch_platform_sim" and "cdpr_control.nodes.visualization" in modules
    assert all(n["parameters"][0].endswith("params/ipanema3.yaml") for n in shown["nodes"])


def test_launch_arguments_after_only_are_launch_arguments():
    """``cdpr launch FILE --only NODE NAME:=VALUE``: --only takes every word that follows, and an argument
    written after it ran the simulator in lockstep while the rest ran free (sync_mode:=latest lost)."""
    run = subprocess.run([sys.executable, "-m", "cdpr_tools.cli", "launch", "cdpr_tools", "closed_loop.yaml",
                          "--only", "winch_platform_sim", "sync_mode:=latest", "robot:=ipanema3", "--show"],
                         capture_output=True, text=True, env=subprocess_env(), timeout=60)
    assert run.returncode == 0, run.stderr
    shown = yaml.safe_load(run.stdout)
    assert shown["parameters"]["sync_mode"] == "latest"
    assert [n["module"] for n in shown["nodes"]] == ["cdpr_sim.nodes.winch_platform_sim"]
    assert shown["nodes"][0]["parameters"][0].endswith("params/ipanema3.yaml")
    alone = subprocess.run([sys.executable, "-m", "cdpr_tools.cli", "launch", "cdpr_tools", "closed_loop.yaml",
                            "--exclude", "sync_mode:=latest", "--show"],
                           capture_output=True, text=True, env=subprocess_env(), timeout=60)
    assert alone.returncode != 0 and "--exclude names no node" in alone.stderr + alone.stdout


@pytest.mark.parametrize("change, message", [
    (lambda t: t + "  - include: {file: other.launch.yaml}\n", r"launch\[5\]: 'include' is not supported by cdpr launch"),
    (lambda t: t.replace("on_exit: shutdown", "respawn: true"), r"launch\[4\] \(node\): 'respawn' is not supported"),
    (lambda t: t.replace("on_exit: shutdown", "on_exit: restart"), "on_exit: restart is not supported"),
    (lambda t: t.replace("talker_params.yaml", "missing.yaml"), "parameter file .*missing.yaml not found"),
    (lambda t: t.replace("exec: listener", "exec: nowhere"), "has no executable 'nowhere'"),
    (lambda t: t.replace("cdpr_test_nodes\n      exec: listener", "cdpr_tools\n      exec: message_convert"),
     "exactly one node class"),
    (lambda t: t.replace("$(var rate)", "$(var speed)"), r"\$\(var speed\) is not declared"),
    (lambda t: t.replace("$(var rate)", "$(eval 2*50)"), r"substitution \$\(eval 2\*50\) is not supported"),
    (lambda t: t.replace("launch:", "nodes:"), "a mapping with one key, 'launch:'"),
])
def test_launch_file_errors_name_the_problem(tmp_path, change, message):
    path = write_graph(tmp_path, "composed", "/a")
    path.write_text(change(path.read_text()))
    with pytest.raises((ValueError, LookupError, FileNotFoundError), match=message) as error:
        description = load_launch_file(path)
        for spec in description.nodes:
            node_class(spec.target()[0])
    assert str(path) in str(error.value) or "exactly one node class" in message
    with pytest.raises(ValueError, match="unknown argument speed; arguments: rate, ns"):
        load_launch_file(write_graph(tmp_path, "composed", "/a"), {"speed": "1"})


def test_composed_graph_runs_in_process_and_records(tmp_path, listen):
    collector = listen.add(Collector, topics={"/comp/heard": Int32})
    launcher = Launcher(load_recorded(tmp_path, "composed", "/comp"))
    with launcher:
        assert {"/comp/chatter", "/comp/heard"} <= set(launcher.recorder.recorded_topics)  # held until recorded
        talker = next(n for n in launcher.nodes if n.get_name() == "talker_x")
        assert talker.get_fully_qualified_name() == "/comp/talker_x"
        assert talker.get_parameter("rate").value == 100.0
        assert talker.get_parameter("gains.kp").value == 2.5  # from the parameter file
        assert talker.get_parameter("greeting").value == "launched"
        wait_for_graph_and_recorder(launcher, collector, "/comp")
    assert not any(t.is_alive() for t in launcher._threads)
    assert not launcher.errors
    check_bag(tmp_path / "composed_bag", "/comp")


def test_processes_graph_runs_and_stops_cleanly(tmp_path, listen, capfd):
    collector = listen.add(Collector, topics={"/proc/heard": Int32})
    launcher = Launcher(load_recorded(tmp_path, "processes", "/proc"), mode="processes", stop_timeout=STOPPING)
    output: list[str] = []
    with launcher:
        assert set(launcher.processes) == {"proc/talker_x", "proc/listener"}
        wait_for_graph_and_recorder(launcher, collector, "/proc")
        # the listener's writer matched both readers (the collector's and the recorder's): the reader's
        # count above is one side of DDS matching; the writer sends only to readers it has matched
        wait_for(lambda: output.append(capfd.readouterr().out) or "heard has 2 subscribers" in "".join(output),
                 timeout=120, what="the listener's publisher to match the recorder")
        start = collector.count("/proc/heard")
        wait_for(lambda: collector.count("/proc/heard") >= start + 5, what="/proc/heard after the match")
    assert launcher.exit_codes == {"proc/talker_x": 0, "proc/listener": 0}
    check_bag(tmp_path / "processes_bag", "/proc")


@pytest.mark.parametrize("mode", ["composed", "processes"])
def test_cdpr_launch_stops_cleanly_on_sigint(tmp_path, listen, mode):
    ns = f"/sig_{mode}"
    collector = listen.add(Collector, topics={f"{ns}/heard": Int32})
    launch = subprocess.Popen([sys.executable, "-m", "cdpr_tools.cli", "launch", str(write_graph(tmp_path, mode, ns)),
                               "--mode", mode, "--record", str(tmp_path / f"{mode}_bag"),
                               "--stop-timeout", str(STOPPING)],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=subprocess_env())
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(launch.stdout), daemon=True)
    reader.start()
    try:
        wait_for(lambda: all(f"subscribed to {ns}/{t}" in "".join(lines) for t in ("chatter", "heard")),
                 timeout=30, what="the recorder")
        # the listener's writer matched both readers (the collector's, the recorder's): DDS matches a
        # new reader asynchronously, and the writer sends only to readers it has matched
        wait_for(lambda: "heard has 2 subscribers" in "".join(lines), timeout=120, what="the recorder's match")
        start = collector.count(f"{ns}/heard")
        wait_for(lambda: collector.count(f"{ns}/heard") >= start + 5, timeout=30, what=f"the {mode} graph")
        launch.send_signal(signal.SIGINT)
        assert launch.wait(STOPPING + 60) == 0, "".join(lines)
    finally:
        if launch.poll() is None:
            launch.kill()
    reader.join(5)
    output = "".join(lines)
    assert "[launch] stopped\n" in output and "Traceback" not in output
    assert "listener stopped after" in output  # the node's destroy_node ran
    check_bag(tmp_path / f"{mode}_bag", ns)


@pytest.mark.parametrize("phase,said", [("import", "slow_start: importing"), ("build", "slow_start: building")])
def test_a_child_stopped_while_it_starts_ends_cleanly(monkeypatch, capfd, phase, said):
    """A launch stopped while a child still imports its node's module, or while the node is being
    built, ends that child with code 0 and no KeyboardInterrupt traceback (a loaded machine may take
    seconds to start thirteen processes; the launch may be stopped meanwhile)."""
    monkeypatch.setenv("CDPR_TEST_SLOW", phase)
    launcher = Launcher(LaunchDescription(nodes=[NodeSpec(module="cdpr_test_nodes.slow_start")]), mode="processes")
    output = []
    with launcher:
        wait_for(lambda: output.append(capfd.readouterr().out) or said in "".join(output), timeout=120,
                 what=f"the child to {phase}")
    output.append(capfd.readouterr().out)
    text = "".join(output)
    assert launcher.exit_codes == {"slow_start": 0}, text
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text
    if phase == "import":
        assert "stopped while starting" in text
    else:
        assert "slow_start destroyed" in text      # the node, once built, was destroyed as usual


def test_a_raising_callback_ends_a_composed_launch_with_the_error(capfd):
    launcher = Launcher(LaunchDescription(nodes=[NodeSpec(module="cdpr_test_nodes.failing"),
                                                 NodeSpec(module="cdpr_test_nodes.listener")]))
    with launcher:
        assert launcher.wait(15)
    assert launcher.errors == ["graph: RuntimeError: boom"]
    assert "RuntimeError: boom" in capfd.readouterr().out  # the traceback, printed under [graph]


@pytest.mark.parametrize("mode,sync_mode", [("composed", "exact"), ("composed", "latest"), ("processes", "latest")])
def test_the_shipped_graph_runs_in_both_modes(listen, mode, sync_mode):
    """closed_loop.yaml (IPAnema 3 Mini, nominal simulator plant) loops and draws markers (a 10 Hz
    timer of the visualization node): composed in lockstep (SingleThreadedExecutor) and
    free-running (EventsExecutor); one process per node free-running. In lockstep, a process graph can
    stall at start-up: the interpreter sends the set-point of t = 0 once, and a node that subscribes
    to /setpoint after that waits for it forever while the simulator repeats only its state."""
    from rclpy.event_handler import EventHandler
    from sensor_msgs.msg import JointState
    from visualization_msgs.msg import MarkerArray

    collector = listen.add(Collector, topics={"/winch/state": JointState, "/winch/command": JointState,
                                              "/visualization/markers": MarkerArray})
    description = load_launch_file(package_share("cdpr_tools") / "graphs" / "closed_loop.yaml",
                                   {"sync_mode": sync_mode})
    with Launcher(description, mode=mode, stop_timeout=STOPPING) as launcher:
        wait_for(lambda: collector.count("/winch/state") > 200 and collector.count("/winch/command") > 200
                 and collector.count("/visualization/markers") > 2, timeout=120, what=f"the {mode} graph to loop and draw")
        assert not launcher.wait(0)  # still running
        if mode == "composed":  # a wait set rebuilt every turn (lockstep) holds no QoS event handlers
            handlers = sum(isinstance(w, EventHandler) for node in launcher.nodes for w in node.waitables)
            assert (handlers == 0) == (sync_mode == "exact"), handlers
    assert not launcher.errors
    assert launcher.exit_codes == dict.fromkeys(launcher.exit_codes, 0)

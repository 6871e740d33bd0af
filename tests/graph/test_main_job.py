"""The main job's path end to end, short: graphs/closed_loop.yaml (IPAnema 3 Mini, composed, lockstep)
recorded to a bag while a short G-code program runs through the RunProgram action; then the bag is
read with rosbags and with mcap_ros2, its topics, types, counts and stamps are checked against each
other and against the control periods, and the run report (cdpr_tools.run_report) is computed from it.
One launch (about 20 s) serves every test of the module.
"""
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from cdpr_test_nodes.graph import wait_for
from cdpr_tools.bag import BagReader
from cdpr_tools.demo_cmd import GRAPH
from cdpr_tools.launch import Launcher, RecordSpec
from cdpr_tools.launch_file import load_launch_file
from cdpr_tools.program_client import run_program
from cdpr_tools.run_report import run_data, summarize

ROBOT = "ipanema3_mini"
PERIOD_NS = 1_000_000
PROGRAM = "G21 G90\nG1 X20 F3000\nG1 X0\nM30"   # 20 mm out along x and back: about 1 s
X_FAR = 0.020                                    # m, the programmed turning point
END_POINT = np.zeros(3)                          # X0 Y0 Z0: the Mini's home, where it starts
SETTLE_S = 0.3                                   # simulated time the loop runs on after the program
LOOP_TYPES = {                                   # one message per control period each
    "/winch/state": "sensor_msgs/msg/JointState",
    "/winch/command": "sensor_msgs/msg/JointState",
    "/setpoint": "cdpr_msgs/msg/OperationalSetpoint",
    "/cable_forces": "cdpr_msgs/msg/CableForces",
    "/platform/pose": "geometry_msgs/msg/PoseStamped",
    "/platform/wrench": "geometry_msgs/msg/WrenchStamped",
    "/forward_kinematics/diagnostics": "cdpr_msgs/msg/ForwardKinematicsDiagnostics",
    "/force_distribution": "cdpr_msgs/msg/ForceDistribution",
    "/cable_force_controller/state": "cdpr_msgs/msg/ControllerState",
    "/cable_force_controller/hand_over": "cdpr_msgs/msg/ControllerState",
    "/ospc/state": "cdpr_msgs/msg/ControllerState",
    "/admittance_controller/setpoint": "cdpr_msgs/msg/OperationalSetpoint",
    "/admittance_controller/state": "cdpr_msgs/msg/ControllerState",
    "/hybrid_force_controller/state": "cdpr_msgs/msg/ControllerState",
    "/load_compensation/state": "cdpr_msgs/msg/ControllerState",
    "/load_compensation/payload": "geometry_msgs/msg/InertiaStamped",
    "/ground_truth/pose": "geometry_msgs/msg/PoseStamped",
    "/ground_truth/twist": "geometry_msgs/msg/TwistStamped",
    "/ground_truth/cable_forces": "cdpr_msgs/msg/CableForces",
    "/ground_truth/external_wrench": "geometry_msgs/msg/WrenchStamped",
}
OTHER_TYPES = {  # present whenever the recorder saw a publisher; the first two always
    "/clock": "rosgraph_msgs/msg/Clock",
    "/program_status": "cdpr_msgs/msg/ProgramStatus",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/rosout": "rcl_interfaces/msg/Log",
    "/parameter_events": "rcl_interfaces/msg/ParameterEvent",
    "/visualization/markers": "visualization_msgs/msg/MarkerArray",  # 10 Hz of wall time
    "/joint_command/mode": "std_msgs/msg/String",                    # latched, on each change
}
TYPES = {**LOOP_TYPES, **OTHER_TYPES}


def stamp_of(msg) -> int:
    stamp = msg.clock if hasattr(msg, "clock") else msg.header.stamp
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def read_rosbags(bag: Path) -> dict:
    """topic -> (type, [(log time, message)]), every message deserialised by rosbags."""
    store = get_typestore(Stores.EMPTY)
    topics = {}
    with Reader(bag) as reader:
        for c in reader.connections:
            store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
            topics[c.topic] = (c.msgtype, [])
        for c, log_time, raw in reader.messages():
            topics[c.topic][1].append((log_time, store.deserialize_cdr(raw, c.msgtype)))
    return topics


def read_mcap_ros2(bag: Path) -> dict:
    """topic -> (schema name, [(log time, message)]), every message decoded by mcap_ros2."""
    (path,) = bag.glob("*.mcap")
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert reader.get_header().profile == "ros2"
        topics = {}
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert (channel.message_encoding, schema.encoding) == ("cdr", "ros2msg"), channel.topic
            topics[channel.topic] = (schema.name, [])
        for _, channel, message, decoded in reader.iter_decoded_messages():
            topics[channel.topic][1].append((message.log_time, decoded))
    return topics


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    bag = tmp_path_factory.mktemp("main_job") / "bag"
    description = load_launch_file(GRAPH, {"robot": ROBOT})
    description.record = RecordSpec(output=str(bag))
    with Launcher(description, mode="composed") as launch:
        sim = next(n for n in launch.nodes if n.get_name() == "winch_platform_sim").sim
        # the launcher holds the composed graph until its recorder records every loop topic
        assert set(LOOP_TYPES) <= set(launch.recorder.recorded_topics)
        result = run_program(PROGRAM, "short", timeout=120.0)
        t_end = sim.t
        wait_for(lambda: sim.t >= t_end + SETTLE_S, timeout=60.0, what="the loop to run on after the program")
    own = BagReader(bag)
    by_topic: dict[str, list] = {}
    for m in own.messages():
        by_topic.setdefault(m.topic.lstrip("/"), []).append(m.msg)
    return SimpleNamespace(result=result, errors=list(launch.errors), periods=sim.steps, bag=bag, own=own,
                           own_messages=by_topic, rosbags=read_rosbags(bag), mcap=read_mcap_ros2(bag))


def test_program_runs_through_the_graph(job):
    assert job.errors == []
    assert job.result.success, job.result.message
    assert job.periods * PERIOD_NS * 1e-9 > job.result.duration + SETTLE_S


def test_every_topic_has_its_type_in_every_reader(job):
    assert set(job.rosbags) == set(job.mcap) == set(job.own.topics)
    assert set(job.rosbags) <= set(TYPES), "unexpected topics"
    assert {*LOOP_TYPES, "/clock", "/program_status"} <= set(job.rosbags)
    for topic, (type_name, _) in job.rosbags.items():
        assert type_name == job.mcap[topic][0] == job.own.topics[topic].type == TYPES[topic], topic
        assert job.own.topics[topic].serialization_format == "cdr"


def test_counts_agree_between_readers_and_with_the_control_periods(job):
    for topic, (_, messages) in job.rosbags.items():
        assert len(messages) == len(job.mcap[topic][1]) == job.own.topics[topic].message_count, topic
    for topic in (*LOOP_TYPES, "/clock"):
        stamps = [stamp_of(m) for _, m in job.rosbags[topic][1]]
        # periods t_0 .. t_N exist; the first ones ran before the recorder subscribed (see job),
        # the last ones may be in flight when the graph stops
        assert len(stamps) <= job.periods + 1, topic
        assert job.periods * PERIOD_NS - stamps[-1] <= 3 * PERIOD_NS, topic
    setpoints = [m for _, m in job.rosbags["/setpoint"][1]]
    first_line = next(i for i, m in enumerate(setpoints) if m.line > 0)
    assert first_line > 0, "the bag must hold the held set-point before the program started"
    for topic in LOOP_TYPES:
        assert stamp_of(job.rosbags[topic][1][0][1]) <= stamp_of(setpoints[first_line]), topic


def test_log_times_are_monotonic_and_equal_in_both_readers(job):
    for topic, (_, messages) in job.rosbags.items():
        log_times = np.array([t for t, _ in messages], dtype=np.int64)
        assert np.all(np.diff(log_times) >= 0), topic
        assert np.array_equal(log_times, [t for t, _ in job.mcap[topic][1]]), topic


def late_start_state(stamps: np.ndarray) -> np.ndarray:
    """stamps without a start state (stamp 0) that the recorder wrote after the first period's message.

    A known race, not yet fixed (seen in 2 of about 8 runs, on a loaded machine): the simulator
    repeats its start state (stamp 0) until the first command, and a recorder subscribing at that
    moment may receive that repetition after the first period's message (bag file order
    pose(1 ms), pose(0), both at log time 0). Only that one message, at the start, is set aside;
    any other step that is not one period still fails."""
    if len(stamps) > 2 and stamps[1] == 0 and stamps[0] == PERIOD_NS:
        return np.delete(stamps, 1)
    return stamps


def test_loop_topic_stamps_advance_by_one_period(job):
    for topic in LOOP_TYPES:
        stamps = late_start_state(np.array([stamp_of(m) for _, m in job.rosbags[topic][1]], dtype=np.int64))
        steps = np.diff(stamps)
        assert np.all(steps == PERIOD_NS), f"{topic}: header stamp steps {sorted(set(steps.tolist()))} ns"
    clock = np.array([stamp_of(m) for _, m in job.rosbags["/clock"][1]], dtype=np.int64)
    assert np.all(np.diff(clock) > 0) and np.all(clock % PERIOD_NS == 0)  # best effort: may skip, never repeat


def test_decoded_messages_agree_between_readers(job):
    for topic in ("/winch/state", "/winch/command"):
        for (_, a), (_, b) in zip(job.rosbags[topic][1], job.mcap[topic][1], strict=True):
            assert stamp_of(a) == stamp_of(b)
            assert list(a.name) == list(b.name) and len(a.position) == 8
            for field in ("position", "velocity", "effort"):
                assert np.array_equal(getattr(a, field), getattr(b, field)), (topic, field)
    for (_, a), (_, b) in zip(job.rosbags["/setpoint"][1], job.mcap["/setpoint"][1], strict=True):
        assert (a.line, a.pose.position.x, a.pose.orientation.w) == (b.line, b.pose.position.x, b.pose.orientation.w)


def test_run_summary_is_finite_and_the_platform_ends_at_the_end_point(job):
    data = run_data(job.own_messages)
    summary = summarize(data)
    assert all(np.isfinite(v) for v in summary.values()), summary
    # the same report from the messages another reader decoded
    foreign = {topic.lstrip("/"): [m for _, m in messages] for topic, (_, messages) in job.mcap.items()}
    assert summarize(run_data(foreign)) == summary
    assert data.x_d[:, 0].max() == pytest.approx(X_FAR, abs=1e-9)
    assert data.x[:, 0].max() > X_FAR - 1e-3, "the platform followed the program"
    np.testing.assert_allclose(data.x_d[-1, :3], END_POINT, atol=1e-9)
    error = np.linalg.norm(data.x[-1, :3] - END_POINT)
    assert error < 1e-3, f"platform ends {1e3 * error:.3f} mm from the programmed end point"


def test_cdpr_plot_writes_the_pngs_of_the_run(job, tmp_path):
    """``cdpr plot BAG``: pose error, cable forces and controller outputs as PNG files."""
    from cdpr_tools.cli import main

    assert main(["plot", str(job.bag), "-o", str(tmp_path)]) == 0
    pngs = sorted(p.name for p in tmp_path.glob("*.png"))
    assert len(pngs) == 3 and all(p.stat().st_size > 10_000 for p in tmp_path.glob("*.png"))

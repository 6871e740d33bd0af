"""The recorder's writer child process (cdpr_tools.bag.writer_process): the same bag as BagWriter,
closed by the child when its parent dies, Ctrl-C handled by the parent; and the recorder composed with
the publishers of a graph takes their message objects, encodes them and records every one."""
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.parameter import Parameter
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from cdpr_control.ros.intraprocess import IntraProcess, IntraProcessNode
from cdpr_tools.bag import BagReader
from cdpr_tools.bag.encode import serialize
from cdpr_tools.bag.recorder import BagRecorder
from cdpr_tools.bag.writer_process import BagWriterProcess
from cdpr_tools.ros_graph import new_context


def joints(k: int) -> JointState:
    return JointState(name=["w1", "w2"], position=[k * 1e-3, 2.0], effort=[float(k)] * 2)


def check_readers(path, count: int) -> None:
    """rosbags (through metadata.yaml) and mcap_ros2 (the file's summary) read every message."""
    store = get_typestore(Stores.EMPTY)
    with RosbagsReader(path) as reader:
        for c in reader.connections:
            store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        assert sum(1 for _ in reader.messages()) == reader.message_count == count
    with open(next(path.glob("*.mcap")), "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_summary().statistics.message_count == count
        assert sum(1 for _ in reader.iter_decoded_messages()) == count


@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_writer_process_writes_the_bag_writer_bag(tmp_path, compression):
    bag = BagWriterProcess(tmp_path / "run", compression=compression, batch=7)
    assert bag.path == tmp_path / "run"
    state = bag.add_topic("/winch/state", "sensor_msgs/msg/JointState")
    status = bag.add_topic("/status", "std_msgs/msg/String")
    assert bag.add_topic("/winch/state", "sensor_msgs/msg/JointState") == state
    for k in range(100):
        bag.put((state, 1_000_000 * (k + 1), serialize(joints(k)), True))
        if k % 10 == 0:
            bag.put((status, 1_000_000 * (k + 1), serialize(String(data=str(k))), True))
    assert bag.message_count == 110
    bag.close()
    bag.close()
    assert not bag.failed
    read = BagReader(tmp_path / "run")
    assert not read.problems and read.message_count == 110
    assert [m.msg.position[0] for m in read.messages(["/winch/state"])] == pytest.approx([k * 1e-3 for k in range(100)])
    assert [m.msg.data for m in read.messages(["/status"])] == [str(k) for k in range(0, 100, 10)]
    check_readers(tmp_path / "run", 110)


def test_writer_process_errors_come_back_to_the_parent(tmp_path):
    (tmp_path / "taken").mkdir()
    with pytest.raises(FileExistsError):
        BagWriterProcess(tmp_path / "taken")
    with pytest.raises(ValueError, match="compression"):
        BagWriterProcess(tmp_path / "x", compression="gzip")
    bag = BagWriterProcess(tmp_path / "y")
    with pytest.raises(LookupError):
        bag.add_topic("/nope", "no_such_pkg/msg/Nope")
    bag.close()
    assert BagReader(tmp_path / "y").message_count == 0


# A process that records JointStates through a writer child as fast as it can: prints the child's
# pid, then how many messages it handed over so far.
PARENT = textwrap.dedent("""
    import sys
    from sensor_msgs.msg import JointState
    from cdpr_tools.bag.encode import serialize
    from cdpr_tools.bag.writer_process import BagWriterProcess
    bag = BagWriterProcess(sys.argv[1], batch=50)
    print(bag.pid, flush=True)
    topic = bag.add_topic("/winch/state", "sensor_msgs/msg/JointState")
    k = 0
    while True:
        bag.put((topic, 1_000_000 * (k + 1), serialize(JointState(position=[k * 1e-3] * 8)), True))
        k += 1
        if k % 50 == 0:
            print(k, flush=True)
""")


def _wait_gone(pid: int, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.05)
    raise AssertionError(f"writer process {pid} still runs")


def test_parent_killed_the_child_closes_the_bag(tmp_path):
    path = tmp_path / "run"
    parent = subprocess.Popen([sys.executable, "-c", PARENT, str(path)], stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    written = 0
    while written < 3000:
        written = int(parent.stdout.readline())
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    _wait_gone(child)      # (not our child: the test cannot wait() for it)
    bag = BagReader(path)
    assert not bag.problems, "the child finished the file: summary and index, no linear scan"
    values = [m.msg.position[0] for m in bag.messages()]
    assert written <= len(values) == bag.message_count          # every batch sent is in the bag
    assert values == pytest.approx([k * 1e-3 for k in range(len(values))])
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["message_count"] == len(values)
    check_readers(path, len(values))


# A composed graph in one process (publisher and recorder share a context) stopped by Ctrl-C.
RECORDING = textwrap.dedent("""
    import signal, sys, time
    # Ctrl-C as in a terminal, also where the test runs in a background job (SIGINT inherited ignored)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState
    from cdpr_control.ros.intraprocess import IntraProcessNode
    from cdpr_tools.bag.recorder import BagRecorder
    from cdpr_tools.ros_graph import new_context
    context = new_context()
    node = IntraProcessNode("talker", context=context)
    pub = node.create_publisher(JointState, "/winch/state", 10)
    recorder = BagRecorder(context=context, parameter_overrides=[
        Parameter("output", value=sys.argv[1]), Parameter("topics", value=["/winch/state"])])
    while not recorder.recorded_topics:
        recorder.selection.discover()
    k = 0
    try:
        while True:
            pub.publish(JointState(position=[float(k)]))
            k += 1
            if k % 100 == 0:
                print(k, flush=True)
            time.sleep(0.0001)
    except KeyboardInterrupt:
        recorder.destroy_node()
        print("published", k, flush=True)
""")


def test_ctrl_c_on_the_process_group_closes_the_bag_with_every_message(tmp_path):
    path = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-c", RECORDING, str(path)], stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    while int(proc.stdout.readline()) < 1000:
        pass
    os.killpg(proc.pid, signal.SIGINT)          # as a terminal does: the writer child gets it too
    try:
        out, _ = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        raise AssertionError("the recording did not stop on SIGINT within 60 s")
    last = out.splitlines()[-1].split()
    assert proc.returncode == 0 and last[0] == "published"
    bag = BagReader(path)
    assert not bag.problems
    assert [m.msg.position[0] for m in bag.messages()] == [float(k) for k in range(int(last[1]))]


def test_composed_recorder_takes_message_objects(tmp_path):
    context = new_context()
    try:
        node = IntraProcessNode("talker", context=context)
        pub = node.create_publisher(JointState, "/winch/state", 10)
        recorder = BagRecorder(context=context, parameter_overrides=[
            Parameter("output", value=str(tmp_path / "run")), Parameter("topics", value=["/winch/state"])])
        while not recorder.recorded_topics:
            recorder.selection.discover()
        local = IntraProcess.of(context).topics["/winch/state"].subscriptions
        assert [s.raw for s in local if s.node is recorder] == [False]   # objects, encoded by the recorder
        sent = [joints(k) for k in range(300)]
        for msg in sent:
            pub.publish(msg)
        assert recorder.writer.message_count == 300
        recorder.destroy_node()
        node.destroy_node()
    finally:
        context.try_shutdown()
    bag = BagReader(tmp_path / "run")
    assert [m.msg for m in bag.messages()] == sent
    times = [m.log_time_ns for m in bag.messages()]
    assert times == sorted(times)
    check_readers(tmp_path / "run", 300)


def test_a_recorder_stopped_behind_its_publishers_records_what_dds_holds_for_it(tmp_path):
    """A recorder in another process (here another context: another DDS participant) that no executor
    spins any more - on a loaded machine its thread lags - still records, when it is destroyed, the
    messages DDS delivered to it. (CI: a launch of two processes recorded 0 of 287 messages of a
    topic whose writer had matched the recorder: its thread had not run since.)"""
    from rclpy.duration import Duration
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    talker_context, recorder_context = new_context(), new_context()
    try:
        node = IntraProcessNode("talker", context=talker_context)
        pub = node.create_publisher(JointState, "/waiting", QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        recorder = BagRecorder(context=recorder_context, parameter_overrides=[
            Parameter("output", value=str(tmp_path / "run")), Parameter("topics", value=["/waiting"])])
        deadline = time.monotonic() + 60
        while not recorder.recorded_topics or pub.get_subscription_count() == 0:   # DDS discovery, both ways
            assert time.monotonic() < deadline, "the recorder did not discover and match /waiting"
            recorder.selection.discover()
            time.sleep(0.01)
        sent = [joints(k) for k in range(50)]
        for msg in sent:
            pub.publish(msg)
        assert pub.wait_for_all_acked(Duration(seconds=60))    # in the recorder's reader history
        assert recorder.writer.message_count == 0              # nothing spun it
        recorder.destroy_node()
        node.destroy_node()
    finally:
        talker_context.try_shutdown()
        recorder_context.try_shutdown()
    assert [m.msg for m in BagReader(tmp_path / "run").messages()] == sent


def test_bags_are_zstd_compressed_by_default_and_every_reader_reads_them(tmp_path):
    """The writer process compresses each chunk with zstd unless told otherwise (issue 27: 982 MiB
    for 174 s of the loop uncompressed); mcap, mcap_ros2, rosbags and the project's reader read it."""
    sizes = {}
    for compression in ("zstd", "none"):
        path = tmp_path / compression
        bag = BagWriterProcess(path) if compression == "zstd" else BagWriterProcess(path, compression="none")
        state = bag.add_topic("/winch/state", "sensor_msgs/msg/JointState")
        for k in range(5000):
            bag.put((state, 1_000_000 * (k + 1), serialize(joints(k)), True))
        bag.close()
        (mcap_file,) = path.glob("*.mcap")
        sizes[compression] = mcap_file.stat().st_size
        with open(mcap_file, "rb") as f:
            chunks = make_reader(f).get_summary().chunk_indexes
        assert {c.compression for c in chunks} == ({"zstd"} if compression == "zstd" else {""})
        check_readers(path, 5000)
        assert BagReader(path).message_count == 5000
    assert sizes["zstd"] < sizes["none"] / 3, sizes

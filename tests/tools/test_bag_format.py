"""Bags in the rosbag2 MCAP layout: written by BagWriter, read back by BagReader, rosbags and mcap_ros2."""
import re

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

from cdpr_msgs.msg import CableForces, ForceDistribution
from geometry_msgs.msg import PoseStamped, WrenchStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty, String

from cdpr_tools.bag import BagReader, BagWriter
from cdpr_tools.bag.cdr import length_function, trimmed
from cdpr_tools.bag.qos import parse_profiles, playback_qos, qos_from_dict, qos_to_dict
from cdpr_tools.bag.schema import SEPARATOR, message_definition, share_dir
from cdpr_tools.message_convert import message_to_dict, type_name_of

T0 = 1_700_000_000_000_000_000  # ns
TEXT = st.characters(blacklist_characters="\x00", blacklist_categories=("Cs",))  # ROS strings: no NUL


def joint_state(i: int) -> JointState:
    names = [f"cable_{k}" for k in range(1, 9)]
    return JointState(name=names, position=[0.1 * i + k for k in range(8)], velocity=[1.0] * 8, effort=[50.0 + i] * 8)


def write_sample_bag(path):
    """A 1 kHz-like set: joint states every ms, forces and wrench every 2 ms, a latched string, raw CDR."""
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    expected = {"/joint_states": 0, "/cable_forces": 0, "/force_distribution": 0, "/wrench": 0,
                "/status": 0, "/empty": 0}
    with BagWriter(path) as bag:
        bag.write("/status", None, String(data="start"), T0, qos=latched)
        expected["/status"] += 1
        for i in range(200):
            t = T0 + i * 1_000_000
            bag.write("/joint_states", "sensor_msgs/msg/JointState", serialize_message(joint_state(i)), t)
            expected["/joint_states"] += 1
            if i % 2 == 0:
                bag.write("/cable_forces", None, CableForces(f=[100.0 + i] * 8, f_min=[10.0] * 8, f_max=[3000.0] * 8), t)
                bag.write("/force_distribution", None, ForceDistribution(f_d=[1.0] * 8, method="qp", iterations=i), t)
                bag.write("/wrench", None, WrenchStamped(), t, qos=QoSProfile(depth=5))
                expected["/cable_forces"] += 1
                expected["/force_distribution"] += 1
                expected["/wrench"] += 1
        bag.write("/empty", None, Empty(), T0 + 200_000_000)
        expected["/empty"] += 1
    return expected


def test_schema_is_rosbag2_concatenation():
    text = message_definition("cdpr_msgs/msg/ForceDistribution")
    own = (share_dir("cdpr_msgs") / "msg" / "ForceDistribution.msg").read_text()
    assert text.startswith(own)
    # nested types depth first, each once, sorted per file, behind rosbag2's separator
    assert re.findall(r"^MSG: (\S+)$", text, re.M) == [
        "geometry_msgs/Wrench", "geometry_msgs/Vector3", "std_msgs/Header", "builtin_interfaces/Time"]
    assert text.count(SEPARATOR) == 4
    assert "\n" + SEPARATOR + "MSG: std_msgs/Header\n" in text
    assert message_definition("std_msgs/msg/String").count("MSG:") == 0


@pytest.mark.parametrize("msg", [
    joint_state(3), Empty(), String(data="abc"), PoseStamped(), WrenchStamped(),
    CableForces(f=[1.0] * 8), ForceDistribution(f_d=[2.0] * 8, method="qp"),
])
def test_cdr_cut_to_encoding_accepted_by_both_decoders(msg):
    name = type_name_of(msg)
    raw = serialize_message(msg)
    cut = trimmed(name, raw)
    assert len(cut) <= len(raw)
    assert trimmed(name, cut) is cut  # exact buffers stay as they are
    assert message_to_dict(deserialize_message(cut, type(msg))) == message_to_dict(msg)
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(message_definition(name), name))
    store.deserialize_cdr(cut, name)  # raises on more than 3 trailing bytes


@settings(max_examples=60, deadline=None)
@given(names=st.lists(st.text(TEXT, max_size=7), max_size=6), pos=st.lists(st.floats(allow_nan=False), max_size=9),
       frame=st.text(TEXT, max_size=9), sec=st.integers(0, 2**31 - 1))
def test_cdr_length_exact_for_any_joint_state(names, pos, frame, sec):
    msg = JointState(name=names, position=pos, effort=pos[:2])
    msg.header.frame_id, msg.header.stamp.sec = frame, sec
    cut = trimmed("sensor_msgs/msg/JointState", serialize_message(msg))
    store = get_typestore(Stores.ROS2_JAZZY)
    decoded = store.deserialize_cdr(cut, "sensor_msgs/msg/JointState")
    assert list(decoded.name) == names and list(decoded.position) == pos and decoded.header.frame_id == frame
    # one byte less is not a whole message any more
    with pytest.raises(Exception):
        deserialize_message(cut[:-1], JointState)


def test_length_function_reads_big_endian_payloads():
    little = trimmed("std_msgs/msg/String", serialize_message(String(data="abcdef")))
    big = bytes([0, 0, 0, 0]) + len("abcdef\0").to_bytes(4, "big") + b"abcdef\0"
    assert length_function("std_msgs/msg/String")(big) == len(big) == len(little)


def test_bag_directory_layout_and_metadata(tmp_path):
    expected = write_sample_bag(tmp_path / "run")
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["metadata.yaml", "run_0.mcap"]
    info = yaml.safe_load((tmp_path / "run" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["run_0.mcap"]
    assert info["message_count"] == sum(expected.values())
    assert info["starting_time"]["nanoseconds_since_epoch"] == T0
    assert info["duration"]["nanoseconds"] == 200_000_000
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert {n: t["message_count"] for n, t in topics.items()} == expected
    status = topics["/status"]["topic_metadata"]
    assert status["type"] == "std_msgs/msg/String" and status["serialization_format"] == "cdr"
    assert status["type_description_hash"].startswith("RIHS01_")
    assert status["offered_qos_profiles"][0]["durability"] == "transient_local"
    assert status["offered_qos_profiles"][0]["reliability"] == "reliable"


def test_mcap_has_summary_indexes_and_ros2_channel_metadata(tmp_path):
    write_sample_bag(tmp_path / "run")
    with open(tmp_path / "run" / "run_0.mcap", "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary.statistics.message_count == 2 + 200 + 3 * 100
        assert summary.chunk_indexes and all(ci.message_index_offsets for ci in summary.chunk_indexes)
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        for channel in summary.channels.values():
            assert channel.message_encoding == "cdr"
            assert channel.metadata["topic_type_hash"].startswith("RIHS01_")
        wrench = next(c for c in summary.channels.values() if c.topic == "/wrench")
        assert parse_profiles(wrench.metadata["offered_qos_profiles"])[0]["depth"] == 5
        embedded = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        assert yaml.safe_load(embedded[0].metadata["serialized_metadata"])["version"] == 9


def test_read_back_with_bag_reader(tmp_path):
    expected = write_sample_bag(tmp_path / "run")
    bag = BagReader(tmp_path / "run")
    assert {t: i.message_count for t, i in bag.topics.items()} == expected
    assert bag.topics["/force_distribution"].type == "cdpr_msgs/msg/ForceDistribution"
    times = [m.log_time_ns for m in bag.messages()]
    assert len(times) == sum(expected.values()) and times == sorted(times)
    states = [m.msg for m in bag.messages(["/joint_states"])]
    assert [list(s.position) for s in states] == [list(joint_state(i).position) for i in range(200)]
    t, position, effort = bag.series("/joint_states", "position", "effort")
    assert t.shape == (200,) and position.shape == (200, 8)
    np.testing.assert_allclose(np.diff(t), 1e-3, atol=1e-9)
    np.testing.assert_allclose(effort[:, 0], 50.0 + np.arange(200))
    with pytest.raises(ValueError, match="topics: /cable_forces"):
        list(bag.messages(["/nope"]))


def test_read_back_with_rosbags_typestore_from_bag_schemas(tmp_path):
    expected = write_sample_bag(tmp_path / "run")
    store = get_typestore(Stores.EMPTY)
    counts = dict.fromkeys(expected, 0)
    with RosbagsReader(tmp_path / "run") as reader:
        for connection in reader.connections:
            store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        last = 0
        for connection, timestamp, raw in reader.messages():
            msg = store.deserialize_cdr(raw, connection.msgtype)
            counts[connection.topic] += 1
            assert timestamp >= last
            last = timestamp
            if connection.topic == "/force_distribution":
                assert msg.method == "qp" and list(msg.f_d) == [1.0] * 8
        types = {c.topic: c.msgtype for c in reader.connections}
    assert counts == expected
    assert types["/cable_forces"] == "cdpr_msgs/msg/CableForces"


def test_read_back_with_mcap_ros2(tmp_path):
    from mcap_ros2.decoder import DecoderFactory

    expected = write_sample_bag(tmp_path / "run")
    counts = dict.fromkeys(expected, 0)
    with open(tmp_path / "run" / "run_0.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        last = 0
        for schema, channel, message, msg in reader.iter_decoded_messages(log_time_order=True):
            counts[channel.topic] += 1
            assert message.log_time >= last
            last = message.log_time
            if channel.topic == "/cable_forces":
                assert schema.name == "cdpr_msgs/msg/CableForces" and list(msg.f_max) == [3000.0] * 8
    assert counts == expected


def test_single_mcap_file_carries_its_metadata(tmp_path):
    with BagWriter(tmp_path / "one.mcap") as bag:
        bag.write("/s", None, String(data="x"), T0)
    assert [p.name for p in tmp_path.iterdir()] == ["one.mcap"]
    reader = BagReader(tmp_path / "one.mcap")
    assert reader.metadata["topics_with_message_count"][0]["topic_metadata"]["name"] == "/s"
    assert [m.msg.data for m in reader.messages()] == ["x"]


def test_writer_refuses_overwrite_and_type_change(tmp_path):
    with BagWriter(tmp_path / "b") as bag:
        bag.write("/s", None, String(data="x"), T0)
        with pytest.raises(ValueError, match="recorded as std_msgs/msg/String"):
            bag.write("/s", None, Empty(), T0)
        with pytest.raises(ValueError, match="give its type name"):
            bag.write("/raw", None, b"\x00\x01\x00\x00", T0)
        with pytest.raises(ValueError, match="not a whole message"):  # string length 16, 2 bytes given
            bag.write("/s", "std_msgs/msg/String", b"\x00\x01\x00\x00\x10\x00\x00\x00ab", T0)
    with pytest.raises(FileExistsError):
        BagWriter(tmp_path / "b")


def test_qos_round_trip_and_playback_choice():
    q = QoSProfile(depth=7, reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    d = qos_to_dict(q)
    assert d["reliability"] == "best_effort" and d["durability"] == "transient_local" and d["history"] == "keep_last"
    back = qos_from_dict(d)
    assert (back.depth, back.reliability, back.durability) == (7, q.reliability, q.durability)
    # version 8 and older wrote policy numbers
    old = qos_from_dict({"history": 3, "depth": 0, "reliability": 1, "durability": 2, "liveliness": 1,
                         "deadline": {"sec": 9223372036, "nsec": 854775807}})
    assert old.reliability == ReliabilityPolicy.RELIABLE and old.durability == DurabilityPolicy.VOLATILE
    assert old.deadline.nanoseconds == 2**63 - 1
    latched = qos_to_dict(QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    play = playback_qos([latched, latched])
    assert play.durability == DurabilityPolicy.TRANSIENT_LOCAL and play.history == HistoryPolicy.KEEP_LAST
    mixed = playback_qos([latched, qos_to_dict(QoSProfile(depth=1))])
    assert mixed.durability != DurabilityPolicy.TRANSIENT_LOCAL


def test_write_serialized_makes_the_file_write_makes(tmp_path):
    """BagWriter.write_serialized (the recorder's writer process) builds MCAP records itself: the
    same bytes as write() through mcap's Writer, over several chunks, exact and cut CDR."""
    from cdpr_tools.bag.encode import serialize
    messages = []
    for i in range(300):
        messages.append(("/joint_states", T0 + i * 1_000_000, serialize(joint_state(i)), True))
        if i % 3 == 0:
            messages.append(("/cable_forces", T0 + i * 1_000_000 - 5, serialize_message(CableForces(f=[1.0 * i])), False))
    files = []
    for how in ("write", "write_serialized"):
        path = tmp_path / how / "run.mcap"     # (the file name is in the rosbag2 metadata record)
        with BagWriter(path, chunk_size=4096, flush_interval=1e9) as bag:
            bag.add_topic("/joint_states", "sensor_msgs/msg/JointState")
            bag.add_topic("/cable_forces", "cdpr_msgs/msg/CableForces")
            if how == "write":
                for topic, t, data, exact in messages:
                    bag.write(topic, None, data, t, exact=exact)
            else:
                bag.write_serialized(messages[:77])
                bag.write_serialized(messages[77:])
        files.append(path.read_bytes())
    assert files[0] == files[1]
    bag = BagReader(tmp_path / "write_serialized" / "run.mcap")
    assert not bag.problems and bag.message_count == len(messages)
    with open(tmp_path / "write_serialized" / "run.mcap", "rb") as f:
        assert len(make_reader(f).get_summary().chunk_indexes) > 5

"""Split bags (ros2 bag record --max-bag-size / --max-bag-duration): numbered .mcap files in one bag
directory, one metadata.yaml listing them; every reader reads the whole bag in order."""
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState

from cdpr_tools import cli
from cdpr_tools.bag import BagReader, BagWriter
from cdpr_tools.bag.encode import serialize
from cdpr_tools.bag.writer_process import BagWriterProcess

N = 6000


def state(k: int) -> JointState:
    return JointState(name=["w1", "w2"], position=[k * 1e-3, 2.0], effort=[float(k)] * 2)


def check_bag(path, files_expected_min: int) -> list:
    metadata = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    files = metadata["relative_file_paths"]
    assert files == [f"{path.name}_{i}.mcap" for i in range(len(files))] and len(files) >= files_expected_min
    assert sorted(p.name for p in path.glob("*.mcap")) == sorted(files)
    assert [f["path"] for f in metadata["files"]] == files
    assert sum(f["message_count"] for f in metadata["files"]) == metadata["message_count"] == N
    starts = [f["starting_time"]["nanoseconds_since_epoch"] for f in metadata["files"]]
    assert starts == sorted(starts)
    for name in files:                         # each file a complete MCAP file of its own
        with open(path / name, "rb") as f:
            assert make_reader(f).get_summary().statistics.message_count > 0
    ours = [m.msg.effort[0] for m in BagReader(path).messages(["/winch/state"])]
    assert ours == [float(k) for k in range(N)]
    store = get_typestore(Stores.ROS2_JAZZY)
    with RosbagsReader(path) as reader:
        theirs = [store.deserialize_cdr(raw, conn.msgtype).effort[0] for conn, _, raw in reader.messages()]
    assert theirs == ours
    return metadata["files"]


def test_split_by_size(tmp_path):
    with BagWriter(tmp_path / "bag", chunk_size=16 * 1024, max_bag_size=64 * 1024) as bag:
        for k in range(N):
            bag.write("/winch/state", "sensor_msgs/msg/JointState", state(k), (k + 1) * 1_000_000)
    check_bag(tmp_path / "bag", 3)
    assert all(p.stat().st_size < 64 * 1024 + 20 * 1024 for p in (tmp_path / "bag").glob("*.mcap"))


def test_split_by_duration_in_the_writer_process(tmp_path):
    bag = BagWriterProcess(tmp_path / "bag", chunk_size=8 * 1024, max_bag_duration=2.0)
    topic = bag.add_topic("/winch/state", "sensor_msgs/msg/JointState")
    for k in range(N):                           # 6 s of log time at 1 kHz
        bag.put((topic, (k + 1) * 1_000_000, serialize(state(k)), True))
    bag.close()
    files = check_bag(tmp_path / "bag", 3)
    assert all(f["duration"]["nanoseconds"] <= 2.2e9 for f in files)


def test_splitting_needs_a_bag_directory_and_sane_limits(tmp_path):
    with pytest.raises(ValueError, match="bag directory"):
        BagWriter(tmp_path / "one.mcap", max_bag_size=1000)
    with pytest.raises(ValueError, match=">= 0"):
        BagWriter(tmp_path / "bag", max_bag_duration=-1.0)
    with pytest.raises(SystemExit):
        cli.main(["bag", "record", "-a", "-o", str(tmp_path / "x"), "--max-bag-size", "-5"])
    with pytest.raises(SystemExit):
        cli.main(["bag", "record", "-a", "-o", str(tmp_path / "x"), "--max-bag-duration", "nan"])

"""Bags cut off by a crash stay readable up to their last complete chunk; a corrupt chunk is skipped
with a report, never silently, and the chunks after it are read; ``cdpr bag reindex`` makes a cut bag
whole for every reader (issue: faults). The corruption cases in detail: test_bag_corruption.py."""
import signal
import subprocess
import sys
import textwrap
import time

import pytest
import yaml
from mcap.reader import make_reader
from sensor_msgs.msg import JointState
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

from cdpr_tools.bag import BagReader, BagWriter
from cdpr_tools.bag.recovery import layout, reindex
from cdpr_tools.cli import main as cdpr

CHUNK = 4096   # bytes: small chunks, so a short recording has many

# A recorder that writes JointStates as fast as it can and says how many it wrote.
WRITER = textwrap.dedent("""
    import sys
    from sensor_msgs.msg import JointState
    from cdpr_tools.bag import BagWriter
    bag = BagWriter(sys.argv[1], chunk_size={chunk})
    k = 0
    while True:
        bag.write("/winch/state", None, JointState(position=[k * 1e-3] * 8), 1_000_000 * (k + 1))
        k += 1
        if k % 50 == 0:
            print(k, flush=True)
""").format(chunk=CHUNK)


def _killed_recording(path, at_least=3000):
    """Start the writer, SIGKILL it once it wrote ``at_least`` messages; the count it last reported."""
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    written = 0
    deadline = time.monotonic() + 60
    while written < at_least and time.monotonic() < deadline:
        written = int(proc.stdout.readline())
    proc.send_signal(signal.SIGKILL)
    for line in proc.stdout:        # what it printed before it died (a loaded machine reads late)
        written = int(line)
    proc.wait()
    assert written >= at_least, "the writer did not get going"
    return written


@pytest.fixture(scope="module")
def killed(tmp_path_factory):
    path = tmp_path_factory.mktemp("crash") / "run"
    written = _killed_recording(path)
    return path, written


def test_killed_bag_reads_up_to_its_last_chunk(killed):
    path, written = killed
    assert (path / "metadata.yaml").is_file(), "metadata.yaml is written when the bag opens"
    bag = BagReader(path)
    assert bag.problems and "linear scan" in bag.problems[0]
    values = [m.msg.position[0] for m in bag.messages(["/winch/state"])]
    # every message before the cut, in order and without gaps; the chunk in progress may be lost
    assert values == pytest.approx([k * 1e-3 for k in range(len(values))])
    per_chunk = CHUNK // 100 + 1                        # a JointState of 8 positions is ~100 bytes
    assert written - 50 - per_chunk <= len(values) <= written + 50
    assert bag.topics["/winch/state"].message_count == len(values) == bag.message_count
    # metadata.yaml counts what was on disk at its last update: never more than the file holds
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert 0 < info["message_count"] <= len(values)


def test_bag_info_of_killed_bag_warns_and_succeeds(killed, capsys):
    path, _ = killed
    assert cdpr(["bag", "info", str(path)]) == 0
    out = capsys.readouterr()
    assert "/winch/state" in out.out and "reindex" in out.err


def test_reindex_makes_the_bag_whole_for_every_reader(killed, tmp_path):
    path, _ = killed
    before = [m.msg.position[0] for m in BagReader(path).messages()]
    report = reindex(path)
    assert any("rewritten" in line for line in report)
    bag = BagReader(path)
    assert not bag.problems
    assert [m.msg.position[0] for m in bag.messages()] == before
    with open(path / "run_0.mcap", "rb") as f:                       # mcap_ros2
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        decoded = [msg.position[0] for _, _, _, msg in reader.iter_decoded_messages(log_time_order=True)]
    assert decoded == before
    store = get_typestore(Stores.EMPTY)                               # rosbags, through metadata.yaml
    with RosbagsReader(path) as reader:
        for c in reader.connections:
            store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        got = [store.deserialize_cdr(raw, c.msgtype).position[0] for c, _, raw in reader.messages()]
        assert reader.message_count == len(before)
    assert got == before
    assert (path / "run_0.mcap.orig").is_file()                       # the user's original is kept
    assert any("rebuilt" in line for line in reindex(path))           # idempotent: nothing to rewrite


def _bag_with_chunks(path, n=600):
    with BagWriter(path, chunk_size=CHUNK) as bag:
        for k in range(n):
            bag.write("/winch/state", None, JointState(position=[float(k)] * 8), 1_000_000 * (k + 1))
    return path


def _corrupt_second_chunk(file):
    with open(file, "rb") as f:
        chunk = make_reader(f).get_summary().chunk_indexes[1]
    with open(file, "r+b") as f:
        f.seek(chunk.chunk_start_offset + chunk.chunk_length - 64)
        f.write(b"\xff" * 16)
    return chunk


def test_corrupt_chunk_is_skipped_with_a_report_not_a_silent_gap(tmp_path):
    path = _bag_with_chunks(tmp_path / "run")
    chunk = _corrupt_second_chunk(path / "run_0.mcap")
    bag = BagReader(path)
    assert len(bag.damage) == 1 and bag.damage[0].start == chunk.chunk_start_offset
    assert "damaged chunk" in bag.problems[0]
    kept = [int(m.msg.position[0]) for m in bag.messages()]
    assert bag.damage[0].lost == 600 - len(kept) == 600 - bag.message_count > 0
    assert kept[0] == 0 and kept[-1] == 599                     # chunks after the bad one survive
    gap = [k for k in range(600) if k not in set(kept)]
    assert gap == list(range(gap[0], gap[0] + len(gap)))        # one contiguous chunk is missing
    assert layout(path / "run_0.mcap").message_count == len(kept)


def test_play_of_a_corrupt_bag_exits_non_zero(tmp_path, capsys):
    path = _bag_with_chunks(tmp_path / "run", n=300)
    _corrupt_second_chunk(path / "run_0.mcap")
    assert cdpr(["bag", "play", str(path), "-r", "100"]) == 1
    captured = capsys.readouterr()
    assert "damaged chunk" in captured.err and "messages lost" in captured.err
    assert f"published {BagReader(path).message_count} messages" in captured.out

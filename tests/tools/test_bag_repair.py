"""`cdpr bag reindex` beyond one file and one kind of damage (issue 28): a split bag with a damaged
chunk in one of its files, a split bag with a file that is no MCAP at all, a rebuild that does not
fit on the disk, and a damaged metadata.yaml. Each asserts how many messages survive against what
the damage allows (computed from the undamaged files' chunk indexes, read with ``mcap``'s reader),
what the exit status is, and that reindex never reports a message it did not write."""
import random
import resource
import shutil
import subprocess
import sys

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState

from cdpr_test_nodes.graph import subprocess_env
from cdpr_tools.bag import BagReader, BagWriter
from cdpr_tools.cli import main as cdpr

N = 3000
CHUNK = 2048             # bytes per chunk
FILE_SIZE = 40_000       # bytes per file of the split bag: about 8 files of about 20 chunks


def log_time(i: int) -> int:
    return (i + 1) * 1_000_000


@pytest.fixture(scope="module")
def split_bag(tmp_path_factory):
    """An undamaged split bag: its path and, per file, its chunks as (offset, length, log times)."""
    path = tmp_path_factory.mktemp("split") / "run"
    with BagWriter(path, chunk_size=CHUNK, max_bag_size=FILE_SIZE) as bag:
        for i in range(N):
            bag.write("/winch/state", None, JointState(position=[float(i)] * 8), log_time(i))
    chunks = {}
    for file in sorted(path.glob("*.mcap")):
        with open(file, "rb") as f:
            indexes = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
        chunks[file.name] = [(c.chunk_start_offset, c.chunk_length,
                              {log_time(i) for i in range(N) if c.message_start_time <= log_time(i) <= c.message_end_time})
                             for c in indexes]
    assert len(chunks) >= 5 and sum(len(t) for c in chunks.values() for _, _, t in c) == N
    return path, chunks


def copy(split_bag, tmp_path):
    path, chunks = split_bag
    shutil.copytree(path, tmp_path / "run")
    return tmp_path / "run", chunks


def flip_a_chunk(bag, chunks, name: str, k: int) -> set[int]:
    """Flip a bit in the middle of chunk ``k`` of file ``name``; the log times it held."""
    offset, length, times = chunks[name][k]
    data = bytearray((bag / name).read_bytes())
    data[offset + length // 2] ^= 0x20
    (bag / name).write_bytes(bytes(data))
    return times


def rosbags_times(bag) -> list[int]:
    store = get_typestore(Stores.ROS2_JAZZY)
    with RosbagsReader(bag) as reader:
        times = [t for _, t, _ in reader.messages()]
        assert reader.message_count == len(times)
        for connection, _, raw in reader.messages():
            store.deserialize_cdr(raw, connection.msgtype)      # decodable, every one
    return times


def mcap_ros2_times(bag) -> list[int]:
    times = []
    for file in yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]["relative_file_paths"]:
        with open(bag / file, "rb") as f:
            times += [m.log_time for _, _, m, _ in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    return times


def test_a_damaged_chunk_in_one_file_of_a_split_bag_costs_that_chunk_only(split_bag, tmp_path, capsys):
    bag, chunks = copy(split_bag, tmp_path)
    middle = sorted(chunks)[len(chunks) // 2]
    lost = flip_a_chunk(bag, chunks, middle, len(chunks[middle]) // 2)
    survive = sorted(set(map(log_time, range(N))) - lost)

    reader = BagReader(bag)
    assert [m.log_time_ns for m in reader.messages()] == survive
    assert reader.lost_messages == (len(lost), 0) and [d.file for d in reader.damage] == [middle]

    assert cdpr(["bag", "play", str(bag), "-r", "1000000"]) == 1
    out, err = capsys.readouterr()
    assert f"published {len(survive)} messages" in out and f"{len(lost)} messages lost" in err

    assert cdpr(["bag", "reindex", str(bag)]) == 0
    out, err = capsys.readouterr()
    in_middle = sum(len(t) for *_, t in chunks[middle]) - len(lost)
    assert f"{middle}: rewritten with {in_middle} messages" in out
    assert f"metadata.yaml: rebuilt ({len(survive)} messages in {len(chunks)} files)" in out
    assert sorted(p.name for p in bag.glob("*.mcap.orig")) == [middle + ".orig"]     # only that file rewritten
    assert rosbags_times(bag) == survive
    assert sorted(mcap_ros2_times(bag)) == survive
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["relative_file_paths"] == sorted(chunks, key=lambda n: int(n[4:-5]))
    assert [f["message_count"] for f in info["files"]] == \
        [sum(len(t - lost) for *_, t in chunks[name]) for name in info["relative_file_paths"]]
    assert BagReader(bag).damage == [] and BagReader(bag).problems == []


def test_a_file_of_a_split_bag_that_is_no_mcap_fails_reindex_and_the_rest_is_repaired(split_bag, tmp_path, capsys):
    bag, chunks = copy(split_bag, tmp_path)
    names = sorted(chunks, key=lambda n: int(n[4:-5]))
    broken = names[2]
    data = (bag / broken).read_bytes()
    (bag / broken).write_bytes(b"\0" * 8 + data[8:])                # its magic bytes gone
    (bag / "metadata.yaml").unlink()
    assert cdpr(["bag", "reindex", str(bag)]) == 1
    out, err = capsys.readouterr()
    assert f"cannot repair {bag / broken}: " in err and "not an MCAP file" in err
    kept = sum(len(t) for name in names if name != broken for *_, t in chunks[name])
    assert f"metadata.yaml: rebuilt ({kept} messages in {len(names) - 1} files)" in out
    assert (bag / broken).read_bytes() == b"\0" * 8 + data[8:]      # left as it was
    assert BagReader(bag).message_count == len(rosbags_times(bag)) == kept


def file_size_limit(limit: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


def test_reindex_that_does_not_fit_on_the_disk_fails_and_leaves_the_file_as_it_was(tmp_path):
    """A bag cut off by a crash, reindexed where the rebuilt file does not fit (a file size limit:
    writes fail with EFBIG as they would with ENOSPC): exit 1 naming the file, no half-written file
    left, the original untouched, no count reported."""
    with BagWriter(tmp_path / "run", chunk_size=CHUNK) as bag:
        for i in range(600):
            bag.write("/winch/state", None, JointState(position=[float(i)] * 8), log_time(i))
    mcap = tmp_path / "run" / "run_0.mcap"
    cut = mcap.read_bytes()[:-3000]                                  # no summary: reindex must rewrite
    mcap.write_bytes(cut)
    metadata = (tmp_path / "run" / "metadata.yaml").read_bytes()
    run = subprocess.run([sys.executable, "-m", "cdpr_tools.cli", "bag", "reindex", str(tmp_path / "run")],
                         env=subprocess_env(), capture_output=True, text=True, timeout=120,
                         preexec_fn=file_size_limit(len(cut) // 2))
    assert run.returncode == 1, run.stdout + run.stderr
    assert f"cdpr bag reindex: error: cannot repair {mcap}: writing run_0.mcap.reindexing failed (File too large)" \
        in run.stderr and "Traceback" not in run.stderr
    assert "rewritten" not in run.stdout and "rebuilt" not in run.stdout
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["metadata.yaml", "run_0.mcap"]
    assert mcap.read_bytes() == cut and (tmp_path / "run" / "metadata.yaml").read_bytes() == metadata
    assert cdpr(["bag", "reindex", str(tmp_path / "run")]) == 0     # with room: whole again
    assert BagReader(tmp_path / "run").damage == []


@pytest.mark.parametrize("text, reason", [
    (b"rosbag2_bagfile_information: [", "not valid YAML"),
    (b"- a\n- b\n", "no rosbag2_bagfile_information mapping"),
    (b"\x89\xff\xfe garbage", "not UTF-8 text"),
    (b"rosbag2_bagfile_information: {relative_file_paths: 7}", "relative_file_paths is not a list"),
    (b"[" * 1500 + b"]" * 1500, "nested deeper than"),
])
def test_a_damaged_metadata_yaml_is_ignored_with_a_warning_and_rebuilt(split_bag, tmp_path, capsys, text, reason):
    bag, _ = copy(split_bag, tmp_path)
    (bag / "metadata.yaml").write_bytes(text)
    reader = BagReader(bag)
    assert [m.log_time_ns for m in reader.messages()] == list(map(log_time, range(N)))
    assert len(reader.problems) == 1 and reader.problems[0].startswith(f"{bag / 'metadata.yaml'}:")
    assert reason in reader.problems[0] and "; ignored: " in reader.problems[0] and reader.damage == []
    assert cdpr(["bag", "play", str(bag), "-r", "1000000"]) == 0         # nothing lost: exit 0, a warning
    out, err = capsys.readouterr()
    assert f"published {N} messages" in out and "metadata.yaml" in err and "; ignored: " in err
    assert cdpr(["bag", "reindex", str(bag)]) == 0
    assert f"metadata.yaml: rebuilt ({N} messages" in capsys.readouterr().out
    assert BagReader(bag).problems == [] and rosbags_times(bag) == list(map(log_time, range(N)))


def test_a_damaged_rosbag2_metadata_record_costs_nothing(split_bag, tmp_path, capsys):
    """The rosbag2 metadata record of a file (outside the chunks, under no CRC) with a control
    character in its YAML: every message is there, play exits 0 (issue 28: a YAML traceback)."""
    bag, chunks = copy(split_bag, tmp_path)
    last = bag / max(chunks, key=lambda n: int(n[4:-5]))            # the writer puts it in the last file
    data = last.read_bytes()
    at = data.index(b"serialized_metadata") + 40
    last.write_bytes(data[:at] + b"\x18" + data[at + 1:])
    reader = BagReader(bag)
    assert reader.message_count == N == len(list(reader.messages())) and reader.damage == []
    assert cdpr(["bag", "play", str(bag), "-r", "1000000"]) == 0
    assert f"published {N} messages" in capsys.readouterr().out


@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_random_damage_keeps_every_chunk_it_did_not_touch(tmp_path, compression):
    """Seeded random damage (bytes inserted, deleted, flipped, zeroed, a range repeated) at random
    places: the reader never raises, returns only recorded messages, each once, in order, keeps
    every chunk the damage did not touch, reports damage whenever it lost something, and reindex
    gives a file that reads back with the same messages and no damage. (A 1000-case run of the same
    found the stray data-end and the resynchronisation losses that named cases in
    test_bag_corruption.py pin down.)"""
    source = tmp_path / "source"
    with BagWriter(source, chunk_size=CHUNK, compression=compression) as bag:
        for i in range(1000):
            bag.write("/winch/state", None, JointState(position=[float(i)] * 8), log_time(i))
    data = (source / "source_0.mcap").read_bytes()
    with open(source / "source_0.mcap", "rb") as f:
        index = make_reader(f).get_summary().chunk_indexes
    chunks = [(c.chunk_start_offset, c.chunk_length,
               {log_time(i) for i in range(1000) if c.message_start_time <= log_time(i) <= c.message_end_time})
              for c in index]
    rng = random.Random(28)
    for trial in range(30):
        kind, at, size = rng.choice(["insert", "delete", "flip", "zero", "repeat"]), \
            rng.randrange(8, len(data)), rng.choice([1, 7, 100, 3000])
        damaged = bytearray(data)
        if kind == "insert":
            damaged[at:at] = rng.randbytes(size)
        elif kind == "delete":
            del damaged[at:at + size]
        elif kind == "flip":
            damaged[at] ^= 1 << rng.randrange(8)
        elif kind == "zero":
            damaged[at:at + size] = bytes(len(damaged[at:at + size]))
        else:
            damaged[at:at] = damaged[at:at + size]
        touched = (at, at + (1 if kind in ("flip", "insert", "repeat") else size))
        keep = {t for offset, length, times in chunks
                if not (offset < touched[1] and touched[0] < offset + length) for t in times}
        bag = tmp_path / f"case{trial}"
        bag.mkdir()
        (bag / "case_0.mcap").write_bytes(bytes(damaged))
        case = f"{kind} of {size} at byte {at}"
        reader = BagReader(bag)
        got = [(m.log_time_ns, m.msg.position[0]) for m in reader.messages()]
        times = [t for t, _ in got]
        assert all(value == t / 1e6 - 1 for t, value in got) and times == sorted(set(times)), case
        assert keep <= set(times), case
        assert len(times) == reader.message_count and (len(times) == 1000 or reader.damage), case
        if not times:
            continue
        assert cdpr(["bag", "reindex", str(bag)]) == 0, case
        again = BagReader(bag)
        assert [m.log_time_ns for m in again.messages()] == times and again.damage == [], case

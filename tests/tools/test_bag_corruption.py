"""Bags that lose only what is damaged (issue 28): a multi-chunk bag is damaged in many ways at
several positions (bit flips, zeroed ranges, truncations, bytes inserted or deleted (one, or a range), duplicated
and reordered chunks, garbage footers), and each reader keeps exactly what the damage allows.

What survives is computed from the chunk boundaries of the undamaged file (its summary's chunk
index, read with ``mcap``'s own reader), not from the code under test: a chunk survives when none
of its bytes changed (other than the two message-time fields of its header, which its CRC does not
cover and no reader needs), or, for a truncated file, when it lies wholly before the cut. Every
message has a log time of its own, so the surviving set is a set of log times. Then, per case:
the project's reader returns exactly those messages, in log-time order, and reports the damage;
``cdpr bag play`` publishes that many and exits 1 when something was skipped; ``cdpr bag reindex``
rebuilds the file, and ``rosbags`` and ``mcap_ros2`` read exactly those messages from it.
"""
import random
import shutil

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from cdpr_tools.bag import BagReader, BagWriter
from cdpr_tools.bag.reader import CorruptBagError
from cdpr_tools.cli import main as cdpr

N = 2000               # messages: a third on /status, the rest on /winch/state
CHUNK = 2048           # bytes per chunk: about 80 chunks
POSITIONS = (0.1, 0.3, 0.5, 0.7, 0.9)
_TIMES = slice(9, 25)  # bytes of a chunk record holding its message start and end time (not under its CRC)


def expected(i: int) -> tuple[str, object]:
    return ("/status", f"s{i}") if i % 3 == 2 else ("/winch/state", float(i))


def log_time(i: int) -> int:
    return (i + 1) * 1_000_000


EXPECTED = {log_time(i): expected(i) for i in range(N)}


@pytest.fixture(scope="module")
def original(tmp_path_factory):
    """The undamaged bag: its file's bytes and its chunks as (offset, length, log times)."""
    path = tmp_path_factory.mktemp("original") / "run"
    with BagWriter(path, chunk_size=CHUNK) as bag:
        for i in range(N):
            topic, value = expected(i)
            msg = String(data=value) if topic == "/status" else JointState(position=[value] * 8)
            bag.write(topic, None, msg, log_time(i))
    data = (path / "run_0.mcap").read_bytes()
    with open(path / "run_0.mcap", "rb") as f:
        indexes = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    chunks = [(c.chunk_start_offset, c.chunk_length,
               {t for t in EXPECTED if c.message_start_time <= t <= c.message_end_time}) for c in indexes]
    assert len(chunks) > 50 and sum(len(c[2]) for c in chunks) == N
    return path, data, chunks


# -- the damage, and what it allows --------------------------------------------------------------
def _survivors_in_place(original_data: bytes, damaged: bytes, chunks) -> set[int]:
    """Same length, bytes changed in place: the chunks none of whose bytes changed (times aside)."""
    keep = set()
    for offset, length, times in chunks:
        before, after = bytearray(original_data[offset:offset + length]), bytearray(damaged[offset:offset + length])
        before[_TIMES] = after[_TIMES] = b"\0" * 16
        if before == after:
            keep |= times
    return keep


def _data_span(chunks, at: float) -> int:
    """A byte offset ``at`` of the way through the chunks' part of the file."""
    start, end = chunks[0][0], chunks[-1][0] + chunks[-1][1]
    return int(start + at * (end - start))


def _chunk_at(chunks, at: float):
    offset = _data_span(chunks, at)
    return next(c for c in chunks if c[0] + c[1] > offset)


def bit_flip_in_records(data, chunks, at):
    offset, length, _ = _chunk_at(chunks, at)
    damaged = bytearray(data)
    damaged[offset + length // 2] ^= 0x20
    return bytes(damaged), _survivors_in_place(data, damaged, chunks)


def bit_flip_in_length(data, chunks, at):
    offset, _, _ = _chunk_at(chunks, at)
    damaged = bytearray(data)
    damaged[offset + 2] ^= 0x01             # the chunk's record length: its end can no longer be trusted
    return bytes(damaged), _survivors_in_place(data, damaged, chunks)


def zeroed(size):
    def damage(data, chunks, at):
        start = _data_span(chunks, at)
        damaged = bytearray(data)
        damaged[start:start + size] = bytes(min(size, len(data) - start))
        return bytes(damaged), _survivors_in_place(data, damaged, chunks)
    damage.__name__ = f"zeroed_{size}"
    return damage


def random_bytes(data, chunks, at):
    start = _data_span(chunks, at)
    damaged = bytearray(data)
    damaged[start:start + 3000] = random.Random(int(at * 100)).randbytes(3000)
    return bytes(damaged), _survivors_in_place(data, damaged, chunks)


def truncated(data, chunks, at):
    cut = _data_span(chunks, at) + 5         # inside a record
    return data[:cut], {t for offset, length, times in chunks if offset + length <= cut for t in times}


def duplicated_chunk(data, chunks, at):
    offset, length, _ = _chunk_at(chunks, at)
    following = next(c[0] for c in chunks if c[0] > offset)   # after the chunk's message index records
    return data[:following] + data[offset:offset + length] + data[following:], set(EXPECTED)


def reordered_chunks(data, chunks, at):
    k = chunks.index(_chunk_at(chunks, at))
    a, b, c = chunks[k][0], chunks[k + 1][0], chunks[k + 2][0]   # two chunks with their message indexes
    return data[:a] + data[b:c] + data[a:b] + data[c:], set(EXPECTED)


def _all_but(chunks, hit) -> set[int]:
    return {t for c in chunks if c is not hit for t in c[2]}


def bytes_inserted_in_a_chunk(data, chunks, at):
    """100 bytes inserted in the middle of a chunk: its length fields still agree, but its true end
    moved, and what follows is read out of step until the next chunk is found again."""
    hit = _chunk_at(chunks, at)
    middle = hit[0] + hit[1] // 2
    return data[:middle] + random.Random(int(at * 100)).randbytes(100) + data[middle:], _all_but(chunks, hit)


def byte_deleted_from_a_chunk(data, chunks, at):
    """One byte gone from the middle of a chunk: the next chunk now starts a byte before where the
    damaged chunk's length says it ends (issue 28: the walk started looking after it, and lost it)."""
    hit = _chunk_at(chunks, at)
    middle = hit[0] + hit[1] // 2
    return data[:middle] + data[middle + 1:], _all_but(chunks, hit)


def stray_opcode(opcode: int, name: str):
    """A byte inserted into a chunk whose last byte now reads as ``opcode``: the walk, out of step by
    a byte, meets that record at the chunk's claimed end, its length made of the real index record's
    bytes (issue 28: taken for the data end, every chunk after it was dropped as "summary, messages
    lost: 0"; taken for a message index, two intact chunks were jumped over)."""
    def damage(data, chunks, at):
        hit = _chunk_at(chunks, at)
        damaged = bytearray(data)
        damaged[hit[0] + hit[1] - 1] = opcode
        middle = hit[0] + hit[1] // 2
        return bytes(damaged[:middle] + b"\xa5" + damaged[middle:]), _all_but(chunks, hit)
    damage.__name__ = f"stray_{name}_after_a_shifted_chunk"
    return damage


def deleted(size):
    """``size`` bytes cut out from the middle of a chunk on: the chunks the range touches are lost,
    those after it come a range earlier than the damaged chunk's length says it ends."""
    def damage(data, chunks, at):
        hit = _chunk_at(chunks, at)
        start = hit[0] + hit[1] // 2
        return data[:start] + data[start + size:], \
            {t for offset, length, times in chunks if not (offset < start + size and start < offset + length)
             for t in times}
    damage.__name__ = f"deleted_{size}"
    return damage


def chunk_opcode_where_a_shortened_chunk_claims_to_end(data, chunks, at):
    """Bytes cut out of a chunk K (its length fields intact) so that the next, shorter chunk now ends
    before K's claimed end, and a chunk opcode there (K+1's index record's, overwritten: no message in
    it): the walk meets a chunk record with a bad length after an intact chunk it has passed over
    (issue 28: it searched on after that record, and lost the intact chunk)."""
    k = chunks.index(_chunk_at(chunks, at))
    k = next(j for j in range(max(k, 1), len(chunks) - 1) if chunks[j][1] - chunks[j + 1][1] >= 60)
    (offset, length, _), (next_offset, next_length, _) = chunks[k], chunks[k + 1]
    index_of_next = next_offset + next_length                 # where K+1's message index records start
    cut = index_of_next - (offset + length)                   # K's claimed end lands there
    first = offset + 49                                       # the first byte after K's header fields
    assert first + cut <= next_offset                         # K+1 itself is not touched
    damaged = bytearray(data)
    damaged[index_of_next] = 0x06
    return bytes(damaged[:first] + damaged[first + cut:]), _all_but(chunks, chunks[k])


def byte_deleted_from_an_index(data, chunks, at):
    """One byte gone from the message index records after an intact chunk: no message is lost."""
    offset, length, _ = _chunk_at(chunks, at)
    following = next(c[0] for c in chunks if c[0] > offset)
    cut = offset + length + (following - offset - length) // 2
    return data[:cut] + data[cut + 1:], set(EXPECTED)


def garbage_footer(data, chunks, at):
    damaged = bytearray(data)
    damaged[-30:] = random.Random(int(at * 100)).randbytes(30)
    return bytes(damaged), set(EXPECTED)


def footer_pointing_into_the_data(data, chunks, at):
    damaged = bytearray(data)                                 # footer: opcode, length, summary start, ...
    damaged[-28:-20] = _data_span(chunks, at).to_bytes(8, "little")
    return bytes(damaged), set(EXPECTED)


def bit_flip_in_the_summary(data, chunks, at):
    end = chunks[-1][0] + chunks[-1][1]                        # the summary follows the data section
    damaged = bytearray(data)
    damaged[int(end + at * (len(data) - end))] ^= 0x04
    return bytes(damaged), set(EXPECTED)


def garbage_after_the_footer(data, chunks, at):
    return data + random.Random(int(at * 100)).randbytes(500), set(EXPECTED)


CASES = [(bit_flip_in_records, at) for at in POSITIONS] \
    + [(damage, at) for damage in (bit_flip_in_length, zeroed(4096), zeroed(65536), random_bytes, truncated)
       for at in POSITIONS[::2]] \
    + [(zeroed(4096), 0.3), (zeroed(65536), 0.7)] \
    + [(damage, at) for damage in (duplicated_chunk, reordered_chunks) for at in (0.1, 0.9)] \
    + [(damage, at) for damage in (bytes_inserted_in_a_chunk, byte_deleted_from_a_chunk) for at in POSITIONS[::2]] \
    + [(byte_deleted_from_an_index, at) for at in (0.3, 0.7)] \
    + [(deleted(5000), at) for at in POSITIONS[::2]] + [(deleted(20000), 0.5)] \
    + [(chunk_opcode_where_a_shortened_chunk_claims_to_end, 0.9)] \
    + [(stray_opcode(opcode, name), at) for opcode, name in ((0x0F, "data_end"), (0x07, "message_index"))
       for at in (0.1, 0.5)] \
    + [(bit_flip_in_the_summary, at) for at in (0.3, 0.6, 0.9)] \
    + [(garbage_footer, 0.0), (garbage_footer, 0.5), (footer_pointing_into_the_data, 0.5),
       (garbage_after_the_footer, 0.0), (bit_flip_in_records, 0.0), (truncated, 0.999)]


@pytest.fixture(params=CASES, ids=lambda case: f"{case[0].__name__}@{case[1]:g}")
def damaged(request, original, tmp_path):
    """A copy of the bag with one kind of damage; (bag path, log times that survive, damaged?)."""
    path, data, chunks = original
    damage, at = request.param
    bad, survive = damage(data, chunks, at)
    assert bad != data
    bag = tmp_path / "run"
    shutil.copytree(path, bag)
    (bag / "run_0.mcap").write_bytes(bad)
    # nothing is skipped when chunks only move, or when only the footer's pointer to the summary is
    # wrong (the file is then read by a linear scan, with a note, and every record in it is intact);
    # a flipped bit in the summary (found by its CRC) costs a summary record or nothing (None: either)
    skipped = None if damage is bit_flip_in_the_summary else \
        damage not in (reordered_chunks, footer_pointing_into_the_data)
    return bag, survive, skipped


# -- the checks ----------------------------------------------------------------------------------
def test_the_project_reader_keeps_every_undamaged_chunk(damaged):
    path, survive, skipped = damaged
    bag = BagReader(path)
    got = [(m.log_time_ns, m.topic, m.msg.data if m.topic == "/status" else m.msg.position[0])
           for m in bag.messages()]
    assert [t for t, _, _ in got] == sorted(survive)           # exactly those, in log-time order
    assert {t: (topic, value) for t, topic, value in got} == {t: EXPECTED[t] for t in survive}
    assert bag.message_count == len(survive)
    assert skipped is None or bool(bag.damage) == skipped
    assert all(d.lost == 0 for d in bag.damage) or skipped
    counted, unknown = bag.lost_messages
    if not unknown:                                            # where the index tells, it tells right
        assert counted == N - len(survive)
    assert counted <= N - len(survive)


def test_bag_play_replays_what_survives_and_exits_1_when_something_was_skipped(damaged, capsys):
    path, survive, skipped = damaged
    code = cdpr(["bag", "play", str(path), "-r", "1000000"])
    out, err = capsys.readouterr()
    assert code == (1 if BagReader(path).damage else 0), err
    assert skipped is None or code == (1 if skipped else 0)
    assert f"published {len(survive)} messages" in out
    for damage in BagReader(path).damage:                      # each skipped part, with its offset
        assert f"  {damage}\n" in err


def test_reindex_rebuilds_a_bag_that_rosbags_and_mcap_ros2_read_in_full(damaged, capsys):
    path, survive, _ = damaged
    code = cdpr(["bag", "reindex", str(path)])
    out, err = capsys.readouterr()
    if not survive:
        assert code == 1 and "cannot repair" in err
        return
    assert code == 0, err
    assert f"({len(survive)} messages)" in out                   # the count it reports is the new file's
    want = {t: EXPECTED[t] for t in survive}
    store = get_typestore(Stores.EMPTY)
    with RosbagsReader(path) as reader:
        for c in reader.connections:
            store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        got = {}
        for c, t, raw in reader.messages():
            msg = store.deserialize_cdr(raw, c.msgtype)
            got[t] = (c.topic, msg.data if c.topic == "/status" else msg.position[0])
        assert reader.message_count == len(survive)
    assert got == want
    with open(path / "run_0.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        got = {m.log_time: (c.topic, msg.data if c.topic == "/status" else msg.position[0])
               for _, c, m, msg in reader.iter_decoded_messages()}
    assert got == want


def test_a_file_with_damaged_magic_is_refused_by_reader_play_and_reindex(original, tmp_path, capsys):
    path, data, _ = original
    bag = tmp_path / "run"
    shutil.copytree(path, bag)
    (bag / "run_0.mcap").write_bytes(b"\x89MCAQ" + data[5:])
    with pytest.raises(CorruptBagError, match="not an MCAP file"):
        BagReader(bag)
    assert cdpr(["bag", "play", str(bag)]) == 1
    assert cdpr(["bag", "reindex", str(bag)]) == 1
    err = capsys.readouterr().err
    assert "not an MCAP file" in err and "cannot repair" in err and "Traceback" not in err
    assert (bag / "run_0.mcap").read_bytes()[5:] == data[5:]        # left as it was
    assert not (bag / "run_0.mcap.orig").exists()


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
@pytest.mark.parametrize("damage", [bit_flip_in_records, zeroed(4096), truncated])
def test_compressed_chunks_lose_only_what_is_damaged(tmp_path, compression, damage):
    """The same for chunks compressed inside the file (a damaged one fails to decompress or its CRC)."""
    path = tmp_path / "run"
    with BagWriter(path, chunk_size=CHUNK, compression=compression) as bag:
        for i in range(600):
            bag.write("/winch/state", None, JointState(position=[float(i)] * 8), log_time(i))
    data = (path / "run_0.mcap").read_bytes()
    with open(path / "run_0.mcap", "rb") as f:
        indexes = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    chunks = [(c.chunk_start_offset, c.chunk_length,
               {log_time(i) for i in range(600) if c.message_start_time <= log_time(i) <= c.message_end_time})
              for c in indexes]
    bad, survive = damage(data, chunks, 0.5)
    (path / "run_0.mcap").write_bytes(bad)
    bag = BagReader(path)
    assert [m.log_time_ns for m in bag.messages()] == sorted(survive)
    assert bag.damage and 0 < len(survive) < 600
    assert [m.msg.position[0] for m in bag.messages()] == [t / 1e6 - 1 for t in sorted(survive)]


def test_messages_whose_channel_record_is_lost_are_counted_lost(original, tmp_path, capsys):
    """No summary (cut) and the first chunk, which holds the channel records, damaged: the other
    chunks' messages cannot be decoded, and they are reported lost, not passed on undecodable."""
    path, data, chunks = original
    bad, _ = bit_flip_in_records(data, chunks, 0.0)
    bad, _ = truncated(bad, chunks, 0.9)
    bag_path = tmp_path / "run"
    shutil.copytree(path, bag_path)
    (bag_path / "run_0.mcap").write_bytes(bad)
    bag = BagReader(bag_path)
    assert bag.message_count == 0 and list(bag.messages()) == []
    intact = sum(len(times) for offset, length, times in chunks[1:] if offset + length <= len(bad))
    lost = [d for d in bag.damage if "channel record" in d.what]
    assert sum(d.lost for d in lost) == intact > 0
    assert cdpr(["bag", "reindex", str(bag_path)]) == 1
    assert "cannot repair" in capsys.readouterr().err


"""Reading MCAP files chunk by chunk, so that damage costs only the chunks it hits.

:func:`layout` finds the intact chunks of a file: through its summary's chunk index when the
summary is readable, matches its CRC and matches the file, otherwise by a linear walk over the
records (a recording cut off by a crash has no summary; a damaged file may have a wrong one; the
summary's chunk index then still tells what a damaged part held). Every chunk is checked
(structure, decompression, CRC of its records) before it counts; a damaged one is skipped and
reported as a :class:`Damage` (file offset, messages lost as far as the chunk index or the message
index records after the chunk tell, otherwise unknown), and the walk goes on with the next chunk:
the next record when the damaged chunk's length fields are consistent, else the next chunk opcode
whose record length is plausible and whose CRC is valid. A chunk repeated byte for byte is read
once. The messages of the intact chunks then come in log-time order from :meth:`McapLayout.messages`.

:func:`reindex` (``cdpr bag reindex``) rewrites a damaged or cut-off file with every message of its
intact chunks, summary and indexes, and reads the new file back before it reports what it holds.

A file whose first bytes are not the MCAP magic is refused (:class:`NotMcapError`): it may not be
MCAP at all, and nothing in it can be trusted to be a record.
"""
from __future__ import annotations

import heapq
import io
import mmap
import os
import struct
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterator

import yaml
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Message, MessageIndex, Metadata, Schema, Statistics
from mcap.writer import CompressionType, IndexType, Writer

from cdpr_tools.bag.qos import parse_profiles
from cdpr_tools.bag.writer import TopicRecord, bag_metadata, write_metadata_yaml

MAGIC = b"\x89MCAP0\r\n"
_HEAD = struct.Struct("<BQ")             # every record: opcode, content length
_CHUNK = struct.Struct("<QQQII")         # chunk: start, end, uncompressed size, CRC, compression length
_MESSAGE = struct.Struct("<HIQQ")        # message: channel id, sequence, log time, publish time
_MESSAGE_INDEX = struct.Struct("<HI")    # message index: channel id, entries length (16 bytes each)
_FOOTER = struct.Struct("<BQQQI")        # footer: opcode, length, summary start, summary offset start, CRC
_COMPRESSIONS = ("", "zstd", "lz4")
# records a data section holds outside chunks, and those of the summary section after DATA_END
# (a message outside a chunk is not read: rosbag2 and this writer always chunk; it is reported)
_DATA_RECORDS = {Opcode.HEADER, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE_INDEX, Opcode.ATTACHMENT,
                 Opcode.METADATA, Opcode.DATA_END}
_SUMMARY_RECORDS = {Opcode.SCHEMA, Opcode.CHANNEL, Opcode.CHUNK_INDEX, Opcode.ATTACHMENT_INDEX,
                    Opcode.METADATA_INDEX, Opcode.STATISTICS, Opcode.SUMMARY_OFFSET}


class NotMcapError(ValueError):
    """The file does not start with the MCAP magic bytes."""


class ChunkError(ValueError):
    """A chunk whose structure, compression or CRC is bad."""


class RepairError(RuntimeError):
    """``reindex`` could not make a readable bag of a file; ``report``: what it did nevertheless."""

    def __init__(self, message: str, report: list[str] | None = None):
        super().__init__(message)
        self.report = list(report or [])


@dataclass(frozen=True)
class Damage:
    """A part of a file that was skipped: bytes [start, end), and the messages it held (None: unknown)."""
    file: str
    start: int
    end: int
    lost: int | None
    what: str

    def __str__(self) -> str:
        lost = "unknown" if self.lost is None else str(self.lost)
        return f"{self.file}: skipped {self.what} at bytes {self.start}-{self.end}; messages lost: {lost}"


@dataclass(frozen=True)
class ChunkRef:
    """An intact chunk: where its record starts, its total length, and its messages' log-time range."""
    offset: int
    length: int
    start: int
    end: int


@dataclass
class McapLayout:
    """What can be read of one MCAP file (see :func:`layout`)."""
    path: Path
    chunks: list[ChunkRef] = field(default_factory=list)         # intact chunks, file order
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    counts: dict[int, int] = field(default_factory=dict)          # channel id -> messages in intact chunks
    metadata: list[Metadata] = field(default_factory=list)
    damage: list[Damage] = field(default_factory=list)
    indexed: bool = False                                         # read through the file's own summary
    complete: bool = False                                        # ends with footer and magic

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())

    @property
    def start_time(self) -> int | None:
        return min((c.start for c in self.chunks), default=None)

    @property
    def end_time(self) -> int | None:
        return max((c.end for c in self.chunks), default=None)

    def messages(self, channels: set[int] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[Message]:
        """Messages of the intact chunks (known channels only) in log-time order, optionally only
        ``channels`` and log times in [start_ns, end_ns).

        Chunks are opened in the order of their first message and merged, so chunks that overlap
        in time still give one ordered stream; only the chunks that can hold the next message are
        in memory.
        """
        wanted = set(self.channels) if channels is None else set(channels) & set(self.channels)
        refs = sorted((c for c in self.chunks
                       if (end_ns is None or c.start < end_ns) and (start_ns is None or c.end >= start_ns)),
                      key=lambda c: (c.start, c.offset))
        heap: list = []
        with open(self.path, "rb") as stream:
            i = 0
            while heap or i < len(refs):
                if i < len(refs) and (not heap or refs[i].start <= heap[0][0]):
                    stream.seek(refs[i].offset)
                    try:
                        _, records = decode_chunk(stream.read(refs[i].length), 0)
                    except ChunkError as exc:                     # it was intact when the layout was made
                        raise ChunkError(f"{self.path}: the chunk at byte {refs[i].offset} changed while "
                                         f"reading ({exc})") from exc
                    for n, m in enumerate(records):
                        if isinstance(m, Message) and m.channel_id in wanted \
                                and (start_ns is None or m.log_time >= start_ns) \
                                and (end_ns is None or m.log_time < end_ns):
                            heapq.heappush(heap, (m.log_time, i, n, m))
                    i += 1
                    continue
                yield heapq.heappop(heap)[3]


# -- one chunk -------------------------------------------------------------------------------
def decode_chunk(buf, offset: int, parse: bool = True) -> tuple[ChunkRef, list]:
    """The chunk record at ``offset`` of ``buf``: its reference and its records (schemas, channels,
    messages; ``parse=False``: none, the check only), or :class:`ChunkError` when its structure,
    compression or CRC is bad."""
    if len(buf) - offset < _HEAD.size + _CHUNK.size:
        raise ChunkError("shorter than a chunk header")
    opcode, length = _HEAD.unpack_from(buf, offset)
    if opcode != Opcode.CHUNK:
        raise ChunkError(f"opcode {opcode:#04x} where a chunk should start")
    end = offset + _HEAD.size + length
    if end > len(buf):
        raise ChunkError(f"record length {length} runs past the end of the file")
    pos = offset + _HEAD.size
    start_time, end_time, size, crc, name_length = _CHUNK.unpack_from(buf, pos)
    pos += _CHUNK.size
    if pos + name_length + 8 > end:
        raise ChunkError("compression name runs past the record")
    compression = bytes(buf[pos:pos + name_length]).decode("ascii", "replace")
    pos += name_length
    (data_length,) = struct.unpack_from("<Q", buf, pos)
    pos += 8
    if compression not in _COMPRESSIONS or pos + data_length != end:
        raise ChunkError(f"inconsistent header (compression {compression!r}, data length {data_length} "
                         f"in a record of {length} bytes)")
    data = _decompress(bytes(buf[pos:end]), compression, size)
    if crc != 0 and zlib.crc32(data) != crc:
        raise ChunkError("CRC of its records does not match")
    if not parse:
        return ChunkRef(offset, end - offset, start_time, end_time), []
    records = _chunk_records(data)
    # the times in the header are not under the CRC: the messages' own times order the chunks
    times = [r.log_time for r in records if isinstance(r, Message)]
    if times:
        start_time, end_time = min(times), max(times)
    return ChunkRef(offset, end - offset, start_time, end_time), records


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    try:
        if compression == "zstd":
            import zstandard
            data = zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        elif compression == "lz4":
            import lz4.frame
            data = lz4.frame.decompress(data)
    except Exception as exc:                                      # noqa: BLE001 - any codec error
        raise ChunkError(f"cannot decompress ({type(exc).__name__}: {exc})") from None
    if len(data) != size:
        raise ChunkError(f"{len(data)} bytes of records where its header says {size}")
    return data


def _chunk_records(data: bytes) -> list:
    records, pos = [], 0
    while pos < len(data):
        if len(data) - pos < _HEAD.size:
            raise ChunkError("a record inside it is cut")
        opcode, length = _HEAD.unpack_from(data, pos)
        body, pos = pos + _HEAD.size, pos + _HEAD.size + length
        if pos > len(data):
            raise ChunkError("a record inside it runs past its end")
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE.size:
                raise ChunkError("a message record shorter than its fields")
            channel_id, sequence, log_time, publish_time = _MESSAGE.unpack_from(data, body)
            records.append(Message(channel_id=channel_id, sequence=sequence, log_time=log_time,
                                   publish_time=publish_time, data=data[body + _MESSAGE.size:pos]))
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            records.append(_parse(opcode, data[body:pos]))
    return records


def _parse(opcode: int, content: bytes):
    """A schema, channel, metadata, message index or statistics record from its content bytes."""
    kind = {Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel, Opcode.METADATA: Metadata,
            Opcode.MESSAGE_INDEX: MessageIndex, Opcode.STATISTICS: Statistics, Opcode.ATTACHMENT: Attachment}[opcode]
    stream = ReadDataStream(io.BytesIO(content))
    try:
        record = kind.read(stream)
    except Exception as exc:                                      # noqa: BLE001 - garbled fields
        raise ChunkError(f"unreadable {kind.__name__} record ({type(exc).__name__})") from None
    if stream.count != len(content):
        raise ChunkError(f"{kind.__name__} record of {len(content)} bytes holds {stream.count}")
    return record


# -- a whole file ----------------------------------------------------------------------------
def layout(path: str | os.PathLike) -> McapLayout:
    """The intact chunks, schemas, channels and message counts of one MCAP file, and what was
    skipped (see the module's docstring). Raises :class:`NotMcapError` for a file without magic."""
    path = Path(path)
    with open(path, "rb") as stream:
        head = stream.read(len(MAGIC))
        if head != MAGIC:
            raise NotMcapError(f"{path}: not an MCAP file (its first bytes are not the MCAP magic"
                               f"{'' if len(head) == len(MAGIC) else '; the file is empty or cut'})")
        summary, metadata = _summary(stream)
        indexed = None if summary is None else _through_summary(path, stream, summary, metadata)
        if indexed is not None:
            return indexed
        found = _walk(path)
        if summary is not None:
            _lost_by_index(found, summary, stream)
    return found


def _summary(stream):
    """The file's summary and metadata records, or (None, None) when it has no readable summary
    (or one whose CRC in the footer does not match it)."""
    if not _summary_crc_matches(stream):
        return None, None
    try:
        stream.seek(0)
        reader = make_reader(stream)
        summary = reader.get_summary()
        metadata = list(reader.iter_metadata())
    except Exception:                                             # noqa: BLE001 - no or garbled footer
        return None, None
    if summary is None or summary.statistics is None or not summary.chunk_indexes and summary.statistics.message_count:
        return None, None
    return summary, metadata


def _summary_crc_matches(stream) -> bool:
    """False when the footer's summary CRC (over the summary section and the footer up to the CRC)
    does not match; True when it does, or when there is no footer to check (mcap decides then)."""
    size = stream.seek(0, os.SEEK_END)
    if size < len(MAGIC) * 2 + _FOOTER.size:
        return True
    stream.seek(size - len(MAGIC) - _FOOTER.size)
    opcode, _, summary_start, _, crc = _FOOTER.unpack(stream.read(_FOOTER.size))
    if opcode != Opcode.FOOTER or crc == 0 or not len(MAGIC) <= summary_start <= size - len(MAGIC) - _FOOTER.size:
        return True
    stream.seek(summary_start)
    return zlib.crc32(stream.read(size - len(MAGIC) - 4 - summary_start)) == crc


def _lost_by_index(found: McapLayout, summary, stream) -> None:
    """Damage of unknown loss that covers chunks the summary indexes: their message index tells."""
    intact = {c.offset for c in found.chunks}
    for k, damage in enumerate(found.damage):
        if damage.lost is not None:
            continue
        hit = [c for c in summary.chunk_indexes
               if damage.start <= c.chunk_start_offset < damage.end and c.chunk_start_offset not in intact]
        counts = [_indexed_counts(stream, c) for c in hit]
        if hit and all(c is not None for c in counts):
            found.damage[k] = replace(damage, lost=sum(sum(c.values()) for c in counts))


def _through_summary(path: Path, stream, summary, metadata) -> McapLayout | None:
    """The layout from the file's summary, or None when the summary does not match the file."""
    found = McapLayout(path, schemas=dict(summary.schemas), channels=dict(summary.channels), metadata=metadata,
                       counts=dict(summary.statistics.channel_message_counts), indexed=True, complete=True)
    for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        stream.seek(index.chunk_start_offset)
        buf = stream.read(index.chunk_length)
        if len(buf) < _HEAD.size + _CHUNK.size or _HEAD.unpack_from(buf)[0] != Opcode.CHUNK \
                or _HEAD.unpack_from(buf)[1] != index.chunk_length - _HEAD.size \
                or _CHUNK.unpack_from(buf, _HEAD.size)[:2] != (index.message_start_time, index.message_end_time):
            return None                                           # the index points elsewhere: walk the file
        try:
            ref, _ = decode_chunk(buf, 0, parse=False)   # (its header's times are the index's, checked above)
        except ChunkError as exc:
            lost = _indexed_counts(stream, index)
            if lost is None:
                return None                                       # exact counts only by walking the file
            for cid, n in lost.items():
                found.counts[cid] = found.counts.get(cid, 0) - n
            found.damage.append(Damage(path.name, index.chunk_start_offset,
                                       index.chunk_start_offset + index.chunk_length, sum(lost.values()),
                                       f"a damaged chunk ({exc})"))
            continue
        found.chunks.append(ChunkRef(index.chunk_start_offset, ref.length, ref.start, ref.end))
    return found


def _indexed_counts(stream, index) -> dict[int, int] | None:
    """Messages per channel of a chunk, from the message index records its chunk index points at."""
    counts = {}
    for cid, offset in index.message_index_offsets.items():
        stream.seek(offset)
        head = stream.read(_HEAD.size + _MESSAGE_INDEX.size)
        if len(head) < _HEAD.size + _MESSAGE_INDEX.size or head[0] != Opcode.MESSAGE_INDEX:
            return None
        channel_id, entries = _MESSAGE_INDEX.unpack_from(head, _HEAD.size)
        if channel_id != cid or entries % 16:
            return None
        counts[cid] = entries // 16
    return counts


class _Walk:
    """The linear walk of :func:`_walk`: record by record, resynchronising after damage."""

    def __init__(self, path: Path, buf):
        self.buf, self.size = buf, len(buf)
        self.found = McapLayout(path)
        self.pending: dict | None = None      # the damaged chunk whose message index records may follow
        self.seen: dict[tuple, int] = {}      # (times, size, CRC) of intact chunks -> their offset
        self.unknown: dict[int, list] = {}    # channel id -> [messages, first and last chunk offset]
        self.after_data_end = False
        # where to look for the next chunk when a record cannot be read: from just after the end of
        # the last chunk whose CRC held (its end is sure), or after the start of a damaged chunk whose length
        # fields agreed (a byte inserted or deleted in it keeps them agreeing but moves its true end,
        # and the records read after it were read out of step: the next chunk may start before the
        # record found unreadable, and searching from there would lose it)
        self.resync = len(MAGIC) + 1

    def run(self) -> McapLayout:
        pos = len(MAGIC)
        while pos < self.size:
            pos = self._record(pos)
        self._close_pending()
        found = self.found
        if not found.complete and not (found.damage and found.damage[-1].end == self.size):
            # cut at a record boundary: whatever came after the cut is gone
            found.damage.append(Damage(found.path.name, self.size, self.size, 0 if self.after_data_end else None,
                                       "the end of the file: it stops without its footer (cut off?)"))
        self._unknown_channels()
        return found

    def _record(self, pos: int) -> int:
        """Read the record at ``pos``; where the walk goes on."""
        if self.size - pos < _HEAD.size:
            return self._skip(pos, self.size, "a record cut off at the end of the file")
        opcode, length = _HEAD.unpack_from(self.buf, pos)
        end = pos + _HEAD.size + length
        if opcode == Opcode.CHUNK and not self.after_data_end:
            return self._chunk(pos)
        if opcode == Opcode.FOOTER and end + len(MAGIC) == self.size and self.buf[end:] == MAGIC:
            self.found.complete = True
            return self.size
        allowed = _SUMMARY_RECORDS if self.after_data_end else _DATA_RECORDS
        if opcode not in allowed or end > self.size or not _plausible(self.buf, pos, opcode, length):
            return self._unreadable(pos, "an unreadable part")
        if opcode == Opcode.MESSAGE_INDEX and self.pending is not None:
            self._count_index(pos, end)
            return end
        self._close_pending()
        if opcode == Opcode.DATA_END:
            self.after_data_end = True
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA):
            try:
                self._add(_parse(opcode, bytes(self.buf[pos + _HEAD.size:end])))
            except ChunkError:
                return self._unreadable(pos, "an unreadable record")
        return end

    def _unreadable(self, pos: int, what: str) -> int:
        """Skip to the next chunk, searched from :attr:`resync`, after an unreadable record at ``pos``."""
        resume = self._next_chunk(min(self.resync, pos + 1))
        if resume > pos:
            return self._skip(pos, resume, what)
        # a chunk begins before the record: the record was read out of step (after a damaged chunk,
        # reported on its own, or a damaged index record); nothing is skipped, the walk steps back
        self._close_pending()
        self.found.damage.append(Damage(self.found.path.name, pos, pos, 0,
                                        f"{what}, read out of step: the walk went on with the chunk at byte {resume}"))
        return resume

    def _chunk(self, pos: int) -> int:
        self._close_pending()
        try:
            ref, records = decode_chunk(self.buf, pos)
        except ChunkError as exc:
            end = _consistent_end(self.buf, pos)
            if end is None:                   # its length cannot be trusted: look for the next chunk
                return self._unreadable(pos, f"a damaged chunk ({exc})")
            self.pending = {"start": pos, "end": end, "lost": 0, "indexed": False, "why": str(exc)}
            self.resync = pos + 1
            return end
        key = _CHUNK.unpack_from(self.buf, pos + _HEAD.size)[:4]
        if key in self.seen:
            self.found.damage.append(Damage(self.found.path.name, pos, pos + ref.length, 0,
                                            f"a repeated copy of the chunk at byte {self.seen[key]}"))
            self.resync = pos + ref.length + 1
            return pos + ref.length
        self.seen[key] = pos
        self.resync = pos + ref.length + 1
        self.found.chunks.append(ref)
        for record in records:
            self._add(record, pos)
        return pos + ref.length

    def _count_index(self, pos: int, end: int) -> None:
        try:
            index = _parse(Opcode.MESSAGE_INDEX, bytes(self.buf[pos + _HEAD.size:end]))
        except ChunkError:
            return
        self.pending["lost"] += len(index.records)
        self.pending["indexed"] = True
        self.pending["end"] = end

    def _close_pending(self) -> None:
        if self.pending is not None:
            p, self.pending = self.pending, None
            self.found.damage.append(Damage(self.found.path.name, p["start"], p["end"],
                                            p["lost"] if p["indexed"] else None, f"a damaged chunk ({p['why']})"))

    def _skip(self, start: int, end: int, what: str) -> int:
        self._close_pending()
        # after DATA_END only the summary follows: its loss costs no message
        lost = 0 if self.after_data_end else None
        if end == self.size and not self.after_data_end and start > len(MAGIC):
            what += "; no intact chunk after it"
        self.found.damage.append(Damage(self.found.path.name, start, end, lost, what))
        return end

    def _next_chunk(self, pos: int) -> int:
        """Offset of the next chunk opcode with a plausible record length and a valid CRC (or the end)."""
        opcode = bytes([Opcode.CHUNK])
        while not self.after_data_end:
            pos = self.buf.find(opcode, pos)
            if pos < 0:
                break
            if _consistent_end(self.buf, pos) is not None:
                try:
                    decode_chunk(self.buf, pos, parse=False)
                    return pos
                except ChunkError:
                    pass
            pos += 1
        return self.size

    def _add(self, record, chunk_offset: int | None = None) -> None:
        found = self.found
        if isinstance(record, Schema):
            found.schemas.setdefault(record.id, record)
        elif isinstance(record, Channel):
            found.channels.setdefault(record.id, record)
        elif isinstance(record, Metadata):
            found.metadata.append(record)
        elif isinstance(record, Message):
            found.counts[record.channel_id] = found.counts.get(record.channel_id, 0) + 1
            seen = self.unknown.setdefault(record.channel_id, [0, chunk_offset, chunk_offset])
            seen[0] += 1
            seen[2] = chunk_offset

    def _unknown_channels(self) -> None:
        """Messages whose channel record was in a damaged part cannot be decoded: count them lost."""
        found = self.found
        for cid, (count, first, last) in self.unknown.items():
            if cid not in found.channels:
                found.counts.pop(cid, None)
                found.damage.append(Damage(found.path.name, first, last, count,
                                           f"the messages of channel {cid} in the chunks from byte {first} to "
                                           f"{last}: its channel record was in a damaged part"))


def _plausible(buf, pos: int, opcode: int, length: int) -> bool:
    """Whether a record outside the chunks (under no CRC) can be what its opcode says: after damage
    the walk may read out of step, and a stray byte taken for the data end (which ends the search
    for chunks) or for a message index with a large length (which jumps over chunks) loses the
    intact chunks after it. The header comes first only; the data end holds a 4-byte CRC; a message
    index holds a channel id and a length-prefixed list of 16-byte entries; an attachment parses
    to its length and matches its CRC (when it has one)."""
    if opcode == Opcode.HEADER:
        return pos == len(MAGIC)
    if opcode == Opcode.DATA_END:
        return length == 4
    if opcode == Opcode.MESSAGE_INDEX:
        if length < _MESSAGE_INDEX.size:
            return False
        entries = _MESSAGE_INDEX.unpack_from(buf, pos + _HEAD.size)[1]
        return entries % 16 == 0 and length == _MESSAGE_INDEX.size + entries
    if opcode == Opcode.ATTACHMENT:
        content = bytes(buf[pos + _HEAD.size:pos + _HEAD.size + length])
        try:
            _parse(opcode, content)
        except ChunkError:
            return False
        (crc,) = struct.unpack_from("<I", content, len(content) - 4)   # it covers all before it
        return crc in (0, zlib.crc32(content[:-4]))
    return True


def _consistent_end(buf, pos: int) -> int | None:
    """End of the chunk record at ``pos`` if its length fields agree with each other, else None."""
    if len(buf) - pos < _HEAD.size + _CHUNK.size + 8 or buf[pos] != Opcode.CHUNK:
        return None
    _, length = _HEAD.unpack_from(buf, pos)
    name_length = _CHUNK.unpack_from(buf, pos + _HEAD.size)[4]
    if name_length > 8:
        return None
    at = pos + _HEAD.size + _CHUNK.size + name_length
    if at + 8 > len(buf):
        return None
    (data_length,) = struct.unpack_from("<Q", buf, at)
    end = at + 8 + data_length
    return end if end == pos + _HEAD.size + length and end <= len(buf) else None


def _walk(path: Path) -> McapLayout:
    with open(path, "rb") as stream, mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ) as buf:
        return _Walk(path, buf).run()      # (mapped: a large file is not read into memory at once)


# -- rebuilding ------------------------------------------------------------------------------
def split_order(file: Path) -> tuple:
    """``bag_2.mcap`` before ``bag_10.mcap`` (a split bag's files in order, without metadata.yaml)."""
    stem, _, number = file.stem.rpartition("_")
    return (stem, int(number)) if number.isdigit() else (file.stem, -1)


def reindex(bag: str | os.PathLike) -> list[str]:
    """Make a cut-off or damaged bag whole again, as ``ros2 bag reindex`` does; returns a report.

    A single ``.mcap`` file, or a bag directory with its .mcap files (one, or the numbered files of
    a split bag, found by their names: a damaged metadata.yaml is not trusted). Each file without a
    summary that matches it, or with damaged parts, is rewritten with every message of its intact
    chunks, summary and indexes (the original is kept beside it as ``<name>.orig``); the new file is
    read back and its count is what the report says. A bag directory then gets a new metadata.yaml
    listing the files that could be read. Raises :class:`RepairError` (its ``report``: what was
    done nevertheless) when a file could not be repaired (not MCAP, no intact chunk with messages,
    or the rebuilt file could not be written: it is then left as it was) or metadata.yaml could not
    be written.
    """
    bag = Path(bag)
    files = [bag] if bag.is_file() else sorted(bag.glob("*.mcap"), key=split_order)
    if not files:
        raise ValueError(f"{bag}: no .mcap file to reindex (a bag directory or an .mcap file)")
    report: list[str] = []
    failed: list[str] = []
    repaired: list[tuple[Path, McapLayout]] = []
    for file in files:
        try:
            repaired.append((file, _reindex_file(file, report)))
        except RepairError as exc:
            failed.append(str(exc))
    if bag.is_dir() and repaired:
        metadata = _directory_metadata_of(repaired)
        try:
            write_metadata_yaml(bag, metadata)
        except OSError as exc:
            (bag / ".metadata.yaml.tmp").unlink(missing_ok=True)
            failed.append(f"cannot write {bag / 'metadata.yaml'}: {exc.strerror or exc}")
        else:
            report.append(f"{bag / 'metadata.yaml'}: rebuilt ({metadata['message_count']} messages"
                          + (f" in {len(repaired)} files)" if len(files) > 1 else ")"))
    if failed:
        raise RepairError("; ".join(failed), report)
    return report


def _reindex_file(file: Path, report: list[str]) -> McapLayout:
    """Rewrite ``file`` when it needs it (adding to ``report``); what it holds afterwards."""
    try:
        found = layout(file)
    except NotMcapError as exc:
        raise RepairError(f"cannot repair {file}: {exc}") from None
    report.extend(str(d) for d in found.damage)
    if found.damage and not found.message_count:
        raise RepairError(f"cannot repair {file}: no intact chunk with messages in it; the file is left as it was")
    if not (found.damage or not found.indexed):
        return found
    original = file.with_name(file.name + ".orig")
    if original.exists():
        raise RepairError(f"cannot repair {file}: {original} exists: move it away before reindexing again")
    tmp = file.with_name(file.name + ".reindexing")
    try:
        counts = rewrite(found, tmp, _metadata_of(file.name, found))
        written = layout(tmp)
    except OSError as exc:                  # a full disk, a file size limit, a read-only directory
        tmp.unlink(missing_ok=True)
        raise RepairError(f"cannot repair {file}: writing {tmp.name} failed ({exc.strerror or exc}); "
                          "the file is left as it was") from None
    if written.damage or not written.indexed or _nonzero(written.counts) != _nonzero(counts):
        tmp.unlink()
        raise RepairError(f"cannot repair {file}: the rebuilt file did not read back as written; "
                          "the file is left as it was")
    os.replace(file, original)
    os.replace(tmp, file)
    report.append(f"{file.name}: rewritten with {written.message_count} messages and its index "
                  f"(read back; the original is kept as {original.name})")
    return written


def _directory_metadata_of(files: list[tuple[Path, McapLayout]]) -> dict:
    """metadata.yaml of a bag directory from what its files hold (topics merged by name)."""
    topics: dict[str, TopicRecord] = {}
    entries = []
    for file, found in files:
        for topic in _metadata_topics(found):
            known = topics.get(topic.name)
            topics[topic.name] = topic if known is None else replace(known, count=known.count + topic.count)
        entries.append({"path": file.name, "start": found.start_time, "end": found.end_time,
                        "count": found.message_count})
    starts = [f.start_time for _, f in files if f.message_count]
    ends = [f.end_time for _, f in files if f.message_count]
    return bag_metadata(entries, list(topics.values()), min(starts, default=None), max(ends, default=None))


def _nonzero(counts: dict[int, int]) -> dict[int, int]:
    return {c: n for c, n in counts.items() if n}


def _metadata_topics(found: McapLayout) -> list[TopicRecord]:
    topics = []
    for cid, ch in found.channels.items():
        schema = found.schemas.get(ch.schema_id)
        topics.append(TopicRecord(ch.topic, schema.name if schema else "",
                                  parse_profiles(ch.metadata.get("offered_qos_profiles")),
                                  ch.metadata.get("topic_type_hash", ""), found.counts.get(cid, 0)))
    return topics


def _metadata_of(file_name: str, found: McapLayout) -> dict:
    return bag_metadata(file_name, _metadata_topics(found), found.start_time, found.end_time)


def rewrite(found: McapLayout, target: str | os.PathLike, metadata: dict | None = None,
            compression: str = "") -> dict[int, int]:
    """Write the readable content of ``found`` as a complete, indexed MCAP file at ``target`` (with
    ``metadata`` as its rosbag2 metadata record, replacing the one found); returns the messages
    written per channel id of ``found``."""
    counts: dict[int, int] = {}
    kinds = {"": CompressionType.NONE, "zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}
    with open(target, "wb") as stream:
        writer = Writer(stream, compression=kinds.get(compression, CompressionType.NONE),
                        index_types=IndexType.ALL, use_chunking=True, use_statistics=True,
                        use_summary_offsets=True)
        writer.start(profile="ros2", library="cdpr_tools bag reindex")
        schema_ids = {sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in found.schemas.items()}
        channel_ids = {}
        for cid, ch in found.channels.items():
            channel_ids[cid] = writer.register_channel(ch.topic, ch.message_encoding,
                                                       schema_ids.get(ch.schema_id, 0), ch.metadata)
        for m in found.messages():
            writer.add_message(channel_ids[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence)
            counts[channel_ids[m.channel_id]] = counts.get(channel_ids[m.channel_id], 0) + 1
        for record in found.metadata:
            if metadata is None or record.name != "rosbag2":
                writer.add_metadata(record.name, record.metadata)
        if metadata is not None:
            writer.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(metadata, sort_keys=False),
                                            "ROS_DISTRO": metadata["ros_distro"]})
        writer.finish()
    return counts

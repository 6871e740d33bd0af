"""Reading MCAP files without a usable summary: a linear scan that keeps every complete chunk.

A recording cut off by a crash has no summary section (no footer, no indexes); a damaged file may
also hold a chunk whose data no longer matches its CRC. :func:`scan` reads such a file record by
record from the start: it keeps every schema, channel and message of each complete, intact chunk,
skips a corrupt chunk with a note (never silently), and stops at the first incomplete record (the
part the crash cut). :func:`rewrite` writes what a scan found as a complete MCAP file with summary
and indexes (``cdpr bag reindex``).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, IndexType, Writer

from cdpr_tools.bag.qos import parse_profiles
from cdpr_tools.bag.writer import TopicRecord, bag_metadata, write_metadata_yaml


@dataclass
class ScanResult:
    path: Path
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)      # log-time order
    metadata: list[Metadata] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)          # what was lost, for the user
    corrupt_chunks: int = 0                                     # chunks skipped for a bad CRC etc.
    complete: bool = False                                      # the file ended with its footer

    def count(self, channel_id: int) -> int:
        return sum(1 for m in self.messages if m.channel_id == channel_id)


def scan(path: str | os.PathLike) -> ScanResult:
    """Every record of ``path`` that can be read, in file order (messages sorted by log time)."""
    result = ScanResult(Path(path))
    size = result.path.stat().st_size
    with open(result.path, "rb") as stream:
        records = StreamReader(stream, emit_chunks=True, record_size_limit=size).records
        offset = 0
        while True:
            try:
                record = next(records)
            except StopIteration:
                result.complete = True
                break
            except Exception as exc:                              # noqa: BLE001 - a cut or garbled record
                offset = stream.tell()
                result.problems.append(
                    f"{result.path.name}: unreadable from about byte {offset} of {size} "
                    f"({type(exc).__name__}: {exc or 'end of file'}); the rest of the file is lost")
                break
            if isinstance(record, Chunk):
                _add_chunk(result, record)
            else:
                _add(result, record)
    result.messages.sort(key=lambda m: (m.log_time, m.channel_id, m.sequence))
    return result


def _add_chunk(result: ScanResult, chunk: Chunk) -> None:
    try:
        inner = breakup_chunk(chunk, validate_crc=True)
    except Exception as exc:                                      # noqa: BLE001 - CRC, decompression
        result.corrupt_chunks += 1
        result.problems.append(
            f"{result.path.name}: corrupt chunk with messages from {chunk.message_start_time} to "
            f"{chunk.message_end_time} ns skipped ({type(exc).__name__}: {exc})")
        return
    for record in inner:
        _add(result, record)


def _add(result: ScanResult, record) -> None:
    if isinstance(record, Schema):
        result.schemas[record.id] = record
    elif isinstance(record, Channel):
        result.channels[record.id] = record
    elif isinstance(record, Message):
        result.messages.append(record)
    elif isinstance(record, Metadata):
        result.metadata.append(record)


def has_summary(path: Path) -> bool:
    with open(path, "rb") as stream:
        try:
            return make_reader(stream).get_summary() is not None
        except Exception:                                         # noqa: BLE001 - no footer
            return False


def reindex(bag: str | os.PathLike) -> list[str]:
    """Make a bag cut off by a crash whole again, as ``ros2 bag reindex`` does; returns a report.

    A single-file bag (``.mcap``) or a bag directory with one .mcap file. A file without summary is
    rewritten with summary and indexes from what a scan reads (the original is kept beside it as
    ``<name>.orig``); a bag directory gets a new metadata.yaml from the file's contents.
    """
    bag = Path(bag)
    files = [bag] if bag.is_file() else sorted(bag.glob("*.mcap"))
    if len(files) != 1:
        raise ValueError(f"{bag}: reindex needs one .mcap file (a bag directory of one file), found {len(files)}")
    file = files[0]
    found = scan(file)
    report = list(found.problems)
    metadata = _metadata_of(file.name, found)
    if not (found.complete and has_summary(file)):
        original = file.with_name(file.name + ".orig")
        if original.exists():
            raise FileExistsError(f"{original} exists: move it away before reindexing again")
        tmp = file.with_name(file.name + ".reindexing")
        rewrite(found, tmp, metadata)
        os.replace(file, original)
        os.replace(tmp, file)
        report.append(f"{file.name}: rewritten with {len(found.messages)} messages and its index "
                      f"(the cut-off original is kept as {original.name})")
    if bag.is_dir():
        write_metadata_yaml(bag, metadata)
        report.append(f"{bag / 'metadata.yaml'}: rebuilt ({metadata['message_count']} messages)")
    return report


def _metadata_of(file_name: str, found: ScanResult) -> dict:
    topics = []
    for cid, ch in found.channels.items():
        schema = found.schemas.get(ch.schema_id)
        topics.append(TopicRecord(ch.topic, schema.name if schema else "",
                                  parse_profiles(ch.metadata.get("offered_qos_profiles")),
                                  ch.metadata.get("topic_type_hash", ""), found.count(cid)))
    times = [m.log_time for m in found.messages]
    return bag_metadata(file_name, topics, min(times, default=None), max(times, default=None))


def rewrite(found: ScanResult, target: str | os.PathLike, metadata: dict | None = None, compression: str = "") -> None:
    """Write the records of a scan as a complete, indexed MCAP file at ``target`` (with ``metadata``
    as its rosbag2 metadata record, replacing the one the scan found)."""
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
        for m in found.messages:
            if m.channel_id in channel_ids:
                writer.add_message(channel_ids[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence)
        for record in found.metadata:
            if metadata is None or record.name != "rosbag2":
                writer.add_metadata(record.name, record.metadata)
        if metadata is not None:
            writer.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(metadata, sort_keys=False),
                                            "ROS_DISTRO": metadata["ros_distro"]})
        writer.finish()

"""BagWriter: ROS messages into one MCAP file in the rosbag2 layout.

What ``ros2 bag record -s mcap`` writes, so that ``ros2 bag info/play``, Foxglove, ``mcap_ros2``
and ``rosbags`` read it: profile ``ros2``; one schema per type (``ros2msg``, nested definitions
appended, see :mod:`.schema`); one channel per topic (encoding ``cdr``, metadata
``offered_qos_profiles`` and ``topic_type_hash``); CDR payloads cut to their encoding
(:mod:`.cdr`); chunks with message indexes, statistics and summary; and a ``rosbag2`` metadata
record holding the bag metadata (version 9). A bag directory also gets rosbag2's metadata.yaml.

A recording cut off by a crash or SIGKILL stays readable up to its last complete chunk, as rosbag2
promises: chunks are bounded in size (``chunk_size``) and in time (``flush_interval``), each one
goes to the operating system as soon as it is complete, and metadata.yaml is written when the bag
opens and updated after every chunk. Such a file lacks its summary section; :class:`BagReader`
then scans it linearly and ``cdpr bag reindex`` rebuilds summary and metadata.

A write that fails (disk full, quota, file size limit: any OSError) stops the bag for good: the
file is cut back to its last complete chunk, metadata.yaml counts what that holds
(:attr:`BagWriter.messages_on_disk`), and :class:`BagWriteError` says so. The file then reads like
one cut off by a crash, and ``cdpr bag reindex`` completes it once there is room.
"""
from __future__ import annotations

import os
import struct
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import yaml
from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import CompressionType, IndexType, Writer
from rclpy.qos import QoSProfile

from cdpr_tools.bag.cdr import trimmed
from cdpr_tools.bag.encode import serialize
from cdpr_tools.bag.qos import dump_profiles, qos_to_dict
from cdpr_tools.bag.schema import ENCODING, message_definition, type_hash
from cdpr_tools.message_convert import type_name_of

METADATA_VERSION = 9  # rosbag2 in ROS 2 Jazzy
SERIALIZATION_FORMAT = "cdr"
_COMPRESSION = {"none": CompressionType.NONE, "zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}
# an MCAP Message record up to its data: opcode, record length, channel id, sequence, log time, publish time
_MESSAGE = struct.Struct("<BQHIQQ")
_MESSAGE_FIELDS = 2 + 4 + 8 + 8


class BagWriteError(OSError):
    """Writing the bag failed (disk full, ...); the bag was stopped at its last complete chunk."""


@dataclass
class _Channel:
    id: int
    topic: str
    type: str
    qos_profiles: list[dict]
    type_hash: str
    count: int = 0


@dataclass
class _Times:
    start: int | None = None
    end: int | None = None

    def add(self, t: int) -> None:
        self.start = t if self.start is None else min(self.start, t)
        self.end = t if self.end is None else max(self.end, t)


class BagWriter:
    """Write ROS messages to a bag.

    ``path`` ending in ``.mcap``: that one file. Any other path: a rosbag2 bag directory
    ``path/`` with ``path/<name>_0.mcap`` and ``path/metadata.yaml``, as ``ros2 bag record -s mcap
    -o path`` makes it. Existing bags are never overwritten. ``opener(path, "wb")`` opens the
    .mcap file (``open``; tests pass one whose file fails as a full disk does).

    ``max_bag_size`` [bytes] / ``max_bag_duration`` [s] (0: no limit; a bag directory only) split
    the bag as ``ros2 bag record --max-bag-size/--max-bag-duration`` does: at the first chunk
    boundary past the limit the file is finished and ``path/<name>_1.mcap``, ``_2``, ... follows;
    metadata.yaml lists every file with its times and count.

    >>> with BagWriter("bags/run1") as bag:
    ...     bag.write("/chatter", "std_msgs/msg/String", String(data="hi"), log_time_ns=t)
    """

    def __init__(self, path: str | os.PathLike, *, compression: str = "none", chunk_size: int = 1 << 20,
                 flush_interval: float = 1.0, opener=open, max_bag_size: int = 0, max_bag_duration: float = 0.0):
        path = Path(path)
        if not (max_bag_size >= 0 and max_bag_duration >= 0):
            raise ValueError(f"max_bag_size and max_bag_duration must be >= 0, got {max_bag_size}, {max_bag_duration}")
        if (max_bag_size or max_bag_duration) and path.suffix == ".mcap":
            raise ValueError(f"{path}: splitting (max_bag_size, max_bag_duration) needs a bag directory, not one .mcap file")
        if path.suffix == ".mcap":
            self.directory, self.mcap_path = None, path
        else:
            self.directory, self.mcap_path = path, path / f"{path.name}_0.mcap"
        for existing in (self.directory, self.mcap_path):
            if existing is not None and existing.exists():
                raise FileExistsError(f"{existing} exists already; choose another bag name")
        if compression not in _COMPRESSION:
            raise ValueError(f"compression must be one of {', '.join(_COMPRESSION)}, got {compression!r}")
        if chunk_size <= 0 or flush_interval <= 0:
            raise ValueError(f"chunk_size and flush_interval must be > 0, got {chunk_size}, {flush_interval}")
        created, parent = [], self.mcap_path.parent       # the directories this bag creates, deepest first
        while not parent.exists() and parent != parent.parent:
            created.append(parent)
            parent = parent.parent
        self.compression = compression
        self.chunk_size = chunk_size
        self.flush_interval = flush_interval
        self.max_bag_size, self.max_bag_duration_ns = int(max_bag_size), int(max_bag_duration * 1e9)
        self._opener = opener
        self.failed: str | None = None   # why writing stopped (BagWriteError), if it did
        self._channels: dict[str, _Channel] = {}
        self._files: list[dict] = []     # the finished files of a split bag: path, start, end, count
        self._file_start: int | None = None   # log time the current file starts at
        self._file_count0 = 0            # messages before the current file
        self._times = _Times()
        self._lock = threading.Lock()
        self._closed = False
        self._pending_bytes = 0
        self._last_flush = time.monotonic()
        self._flushed = {"count": 0, "times": _Times(), "counts": {}}   # what is on disk
        try:
            self.mcap_path.parent.mkdir(parents=True, exist_ok=True)
            self._open_file()
            self._on_disk(self._write_metadata_file)
        except OSError:                  # (BagWriteError too) a full disk at the start: leave nothing
            self._remove(created)        # behind, so that the same name can be used again
            raise

    def _remove(self, created: list[Path]) -> None:
        """Remove what a bag that failed as it opened wrote (no message yet), and the directories it made."""
        stream = getattr(self, "_stream", None)
        if stream is not None and not stream.closed:
            try:
                stream.close()
            except OSError:
                pass
        extra = [] if self.directory is None else [self.directory / "metadata.yaml", self.directory / ".metadata.yaml.tmp"]
        for file in (self.mcap_path, *extra):
            file.unlink(missing_ok=True)
        for directory in created:
            try:
                directory.rmdir()
            except OSError:
                pass

    def _open_file(self) -> None:
        """Start the bag's (next) .mcap file: header, and every schema and channel declared so far."""
        self._stream = self._opener(self.mcap_path, "wb")
        # the chunks are cut here (_maybe_flush), by size and by age, not by the mcap writer
        self._mcap = Writer(self._stream, chunk_size=1 << 62, compression=_COMPRESSION[self.compression],
                            index_types=IndexType.ALL, use_chunking=True, use_statistics=True,
                            use_summary_offsets=True)
        self._mcap.start(profile="ros2", library="cdpr_tools bag writer (rosbag2 layout)")
        self._good_size = 0              # bytes of the file that hold complete records
        self._schemas: dict[str, int] = {}
        for channel in self._channels.values():
            channel.id = self._register(channel.topic, channel.type, channel.qos_profiles, channel.type_hash)
        self._on_disk(lambda: None)      # the header, so the file is MCAP

    def _register(self, topic: str, type_name: str, profiles: list[dict], digest: str) -> int:
        if type_name not in self._schemas:
            self._schemas[type_name] = self._mcap.register_schema(
                name=type_name, encoding=ENCODING, data=message_definition(type_name).encode())
        return self._mcap.register_channel(
            topic=topic, message_encoding=SERIALIZATION_FORMAT, schema_id=self._schemas[type_name],
            metadata={"offered_qos_profiles": dump_profiles(profiles), "topic_type_hash": digest})

    def _split_due(self) -> bool:
        if self.max_bag_size and self._good_size >= self.max_bag_size:
            return True
        return bool(self.max_bag_duration_ns and self._file_start is not None and self._times.end is not None
                    and self._times.end - self._file_start >= self.max_bag_duration_ns)

    def _next_file(self) -> None:
        """Finish the current file (summary, footer) and go on in ``<name>_<k+1>.mcap``."""
        self._files.append(self._current_file())
        self._on_disk(self._mcap.finish)
        self._on_disk(self._stream.close)
        self.mcap_path = self.directory / f"{self.directory.name}_{len(self._files)}.mcap"
        if self.mcap_path.exists():
            raise FileExistsError(f"{self.mcap_path} exists already")
        self._file_start, self._file_count0 = None, self.message_count
        self._open_file()

    def _current_file(self) -> dict:
        return {"path": self.mcap_path.name, "start": self._file_start, "end": self._times.end,
                "count": self.message_count - self._file_count0}

    # -- topics ------------------------------------------------------------------------------
    def add_topic(self, topic: str, type_name: str, qos: Any = None, type_description_hash: str | None = None) -> None:
        """Declare a topic before (or without) writing to it.

        ``qos``: the offered QoS, a ``QoSProfile``, a rosbag2 profile dict or a list of either (one
        per publisher); ``type_description_hash``: ``RIHS01_...``, by default from the installed type.
        """
        with self._lock:
            self._add_topic(topic, type_name, qos, type_description_hash)

    def _check_open(self) -> None:
        if self.failed is not None:
            raise BagWriteError(self.failed)
        if self._closed:
            raise ValueError(f"bag {self.path} is closed")

    def _add_topic(self, topic: str, type_name: str, qos: Any, type_description_hash: str | None) -> _Channel:
        self._check_open()
        if topic in self._channels:
            channel = self._channels[topic]
            if channel.type != type_name:
                raise ValueError(f"topic {topic} is recorded as {channel.type}, not {type_name}")
            return channel
        profiles = _profiles(qos)
        digest = type_hash(type_name) if type_description_hash is None else type_description_hash
        channel = _Channel(self._register(topic, type_name, profiles, digest), topic, type_name, profiles, digest)
        self._channels[topic] = channel
        return channel

    @property
    def topics(self) -> dict[str, str]:
        """Topic -> type of everything declared so far."""
        return {t: c.type for t, c in self._channels.items()}

    # -- messages ----------------------------------------------------------------------------
    def write(self, topic: str, type_name: str | None, data: Any, log_time_ns: int,
              qos: Any = None, publish_time_ns: int | None = None, exact: bool = False) -> None:
        """Write one message: ``data`` is a message instance or its CDR bytes.

        ``log_time_ns`` is the receive time (sim time when the graph runs on /clock), which orders
        the bag; ``type_name`` may be None for a message instance; ``qos`` is used on the topic's
        first message only (see :meth:`add_topic`); ``exact``: the bytes hold the encoding and
        nothing after it (as :mod:`.encode` makes them), so they need no cut.
        """
        if not isinstance(data, (bytes, bytearray, memoryview)):
            type_name = type_name or type_name_of(data)
            data, exact = serialize(data, type_name), True
        with self._lock:
            self._check_open()
            channel = self._channels.get(topic)
            if channel is None or (type_name is not None and type_name != channel.type):
                if type_name is None:
                    raise ValueError(f"first message on {topic}: give its type name")
                channel = self._add_topic(topic, type_name, qos, None)
            if not exact:
                data = trimmed(channel.type, data)
            channel.count += 1
            self._times.add(log_time_ns)
            if self._file_start is None:
                self._file_start = log_time_ns
            self._mcap.add_message(channel.id, log_time_ns, bytes(data),
                                   log_time_ns if publish_time_ns is None else publish_time_ns, channel.count)
            self._pending_bytes += len(data)
            self._maybe_flush()

    def write_serialized(self, messages: Iterable[tuple[str, int, bytes, bool]]) -> None:
        """Write ``(topic, log_time_ns, cdr, exact)`` of declared topics (:meth:`add_topic`) in
        order: the file :meth:`write` makes of them, at a third of its cost (the recorder's
        writer process spends most of its time here).

        The MCAP Message records go into the chunk in one struct call each, with the chunk's
        message index, times and count and the file's statistics updated as ``mcap``'s
        ``Writer.add_message`` does (mcap 1.6, pinned in constraints.txt; tests/tools/test_bag_format.py
        compares the two files byte for byte).
        """
        with self._lock:
            self._check_open()
            channels, times, chunk_size = self._channels, self._times, self.chunk_size
            stats = self._mcap._Writer__statistics
            counts = stats.channel_message_counts
            chunk = self._mcap._Writer__chunk_builder
            records, indexes = chunk.record_writer._buffer, chunk.message_indices
            for topic, log_time, data, exact in messages:
                if self._file_start is None:
                    self._file_start = log_time
                channel = channels.get(topic)
                if channel is None:
                    raise ValueError(f"{topic}: declare the topic (add_topic) before writing serialized messages")
                if not exact:
                    data = trimmed(channel.type, data)
                channel.count += 1
                if times.start is None:
                    times.start = times.end = log_time
                else:
                    times.start, times.end = min(times.start, log_time), max(times.end, log_time)
                if stats.message_count == 0:
                    stats.message_start_time = log_time
                else:
                    stats.message_start_time = min(log_time, stats.message_start_time)
                stats.message_end_time = max(log_time, stats.message_end_time)
                counts[channel.id] += 1
                stats.message_count += 1
                if chunk.num_messages == 0:
                    chunk.message_start_time = log_time
                else:
                    chunk.message_start_time = min(chunk.message_start_time, log_time)
                chunk.message_end_time = max(chunk.message_end_time, log_time)
                index = indexes.get(channel.id)
                if index is None:
                    index = indexes[channel.id] = MessageIndex(channel_id=channel.id, records=[])
                index.records.append((log_time, records.tell()))
                chunk.num_messages += 1
                records.write(_MESSAGE.pack(Opcode.MESSAGE, _MESSAGE_FIELDS + len(data), channel.id, channel.count,
                                            log_time, log_time))
                records.write(data)
                self._pending_bytes += len(data)
                if self._pending_bytes >= chunk_size:
                    self._flush()                           # (maybe into the next file of a split bag)
                    stats = self._mcap._Writer__statistics
                    counts = stats.channel_message_counts
                    chunk = self._mcap._Writer__chunk_builder
                    records, indexes = chunk.record_writer._buffer, chunk.message_indices
            self._maybe_flush()

    def flush(self) -> None:
        """End the chunk in progress and put it on disk with an updated metadata.yaml."""
        with self._lock:
            if not self._closed:
                self._flush()

    def flush_due(self) -> None:
        """Flush if the chunk in progress is older than ``flush_interval`` (chunks are otherwise
        cut by :meth:`write`: a writer whose messages stop calls this now and then)."""
        with self._lock:
            if not self._closed and self._pending_bytes and time.monotonic() - self._last_flush >= self.flush_interval:
                self._flush()

    def _maybe_flush(self) -> None:
        if self._pending_bytes >= self.chunk_size or time.monotonic() - self._last_flush >= self.flush_interval:
            self._flush()

    def _flush(self) -> None:
        self._on_disk(self._mcap.flush)  # ends the chunk and flushes the stream: on disk despite SIGKILL
        if self._split_due():
            self._next_file()
        self._pending_bytes = 0
        self._last_flush = time.monotonic()
        self._flushed = {"count": self.message_count, "times": _Times(self._times.start, self._times.end),
                         "counts": {t: c.count for t, c in self._channels.items()}}
        self._on_disk(self._write_metadata_file)

    def _on_disk(self, write) -> None:
        """Run ``write`` and flush the .mcap stream, so that what it holds so far is on disk and
        complete; on an OSError stop the bag at the last such point (:meth:`_fail`)."""
        try:
            write()
            if not self._stream.closed:
                self._stream.flush()
        except OSError as exc:
            self._fail(exc)
        if not self._stream.closed:
            self._good_size = self._stream.tell()

    def _fail(self, exc: OSError) -> None:
        """Stop for good: cut the file back to its last complete record, count what it holds in
        metadata.yaml (best effort: the disk may still be full), raise BagWriteError."""
        self._closed = True
        try:
            self._stream.close()                # may write more of the broken chunk: cut below
        except OSError:
            pass
        os.truncate(self.mcap_path, self._good_size)
        try:
            self._write_metadata_file()
        except OSError:
            (self.directory / ".metadata.yaml.tmp").unlink(missing_ok=True)
        self.failed = (f"writing {self.mcap_path} failed ({exc.strerror or exc}): recording stopped; "
                       f"{self.messages_on_disk} messages are on disk (the file ends at its last complete "
                       "chunk; `cdpr bag reindex` adds its index once there is room)")
        raise BagWriteError(self.failed) from exc

    @property
    def messages_on_disk(self) -> int:
        """Messages in the complete chunks on disk (all of them once the bag is closed)."""
        return self._flushed["count"]

    @property
    def message_count(self) -> int:
        return sum(c.count for c in self._channels.values())

    @property
    def path(self) -> Path:
        """What to hand to readers and ``ros2 bag``: the bag directory, or the single .mcap file."""
        return self.directory or self.mcap_path

    # -- closing -----------------------------------------------------------------------------
    def metadata(self, on_disk: bool = False) -> dict:
        """rosbag2's bag metadata (the mapping under ``rosbag2_bagfile_information``); ``on_disk``:
        of what the finished chunks hold (while recording), else of everything written."""
        times = self._flushed["times"] if on_disk else self._times
        counts = self._flushed["counts"] if on_disk else {t: c.count for t, c in self._channels.items()}
        topics = [TopicRecord(c.topic, c.type, c.qos_profiles, c.type_hash, counts.get(c.topic, 0))
                  for c in self._channels.values()]
        current = self._current_file()
        if on_disk and not self._closed:          # of the current file, what its finished chunks hold
            current["end"] = times.end
            current["count"] = self._flushed["count"] - self._file_count0
        return bag_metadata(self._files + [current], topics, times.start, times.end)

    def close(self) -> None:
        """Finish the MCAP file (summary, indexes) and write metadata.yaml; safe to call twice."""
        with self._lock:
            if self._closed:
                return
            metadata = self.metadata()
            self._mcap.add_metadata("rosbag2", {"serialized_metadata": _yaml(metadata),
                                                "ROS_DISTRO": metadata["ros_distro"]})
            self._on_disk(self._mcap.finish)      # the last chunk, summary and footer
            self._on_disk(self._stream.close)
            self._closed = True
            self._flushed = {"count": self.message_count, "times": self._times,
                             "counts": {t: c.count for t, c in self._channels.items()}}
            self._on_disk(lambda: self._write_metadata_file(metadata))

    def _write_metadata_file(self, metadata: dict | None = None) -> None:
        """metadata.yaml of a bag directory, replaced atomically (a crash leaves the old or the new)."""
        if self.directory is None:
            return
        write_metadata_yaml(self.directory, self.metadata(on_disk=True) if metadata is None else metadata)

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass(frozen=True)
class TopicRecord:
    """One topic of a bag as rosbag2's metadata lists it."""
    name: str
    type: str
    qos_profiles: list[dict]
    type_hash: str
    count: int


def bag_metadata(files: str | list[dict], topics: list[TopicRecord], start_ns: int | None,
                 end_ns: int | None) -> dict:
    """rosbag2's bag metadata (version 9) of an MCAP bag: ``files`` its file name (one file) or its
    files in order, each ``{"path", "start", "end", "count"}`` (times [ns], None without messages)."""
    start = start_ns or 0
    duration = (end_ns - start) if end_ns is not None else 0
    total = sum(t.count for t in topics)
    if isinstance(files, str):
        files = [{"path": files, "start": start_ns, "end": end_ns, "count": total}]
    return {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": total,
        "topics_with_message_count": [
            {"topic_metadata": {"name": t.name, "type": t.type, "serialization_format": SERIALIZATION_FORMAT,
                                "offered_qos_profiles": t.qos_profiles, "type_description_hash": t.type_hash},
             "message_count": t.count}
            for t in topics],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f["path"] for f in files],
        "files": [{"path": f["path"], "starting_time": {"nanoseconds_since_epoch": f["start"] or 0},
                   "duration": {"nanoseconds": (f["end"] - f["start"]) if f["start"] is not None else 0},
                   "message_count": f["count"]} for f in files],
        "custom_data": None,
        "ros_distro": os.environ.get("ROS_DISTRO", "jazzy"),
    }


def _profiles(qos: Any) -> list[dict]:
    if qos is None:
        return []
    items: Iterable = qos if isinstance(qos, (list, tuple)) else [qos]
    return [qos_to_dict(q) if isinstance(q, QoSProfile) else dict(q) for q in items]


def write_metadata_yaml(directory: Path, metadata: dict) -> None:
    """Write ``directory/metadata.yaml`` (rosbag2's bag metadata) atomically."""
    tmp = directory / ".metadata.yaml.tmp"
    tmp.write_text(_yaml({"rosbag2_bagfile_information": metadata}))
    os.replace(tmp, directory / "metadata.yaml")


def _yaml(data: dict) -> str:
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False)

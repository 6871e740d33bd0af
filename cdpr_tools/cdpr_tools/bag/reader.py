"""BagReader: messages, types and timestamps out of rosbag2 MCAP bags.

Reads what :class:`~cdpr_tools.bag.writer.BagWriter` and ``ros2 bag record -s mcap`` write: a
bag directory (metadata.yaml and one or more .mcap files) or a single .mcap file. Messages come in
receive-time (log time) order and deserialise lazily with the installed message classes.

Each file is read chunk by chunk (:mod:`.recovery`): through its summary's chunk index, or by a
linear scan when it has no summary (a recording cut off by a crash) or one that does not match the
file. A chunk whose structure or CRC is bad is skipped and the reading goes on with the next one;
every part skipped is in :attr:`BagReader.damage` (file offset, messages lost where the index
tells) and, for the user, in :attr:`BagReader.problems`. A file that is not MCAP at all is refused.
"""
from __future__ import annotations

import functools
import heapq
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np
import yaml
from rclpy.serialization import deserialize_message

from cdpr_control.model.yaml_file import YamlFileError, load_yaml
from cdpr_tools.bag.qos import parse_profiles
from cdpr_tools.bag.recovery import ChunkError, Damage, McapLayout, NotMcapError, layout, split_order
from cdpr_tools.message_convert import field_value, message_class
from cdpr_tools.progress import track


class CorruptBagError(ValueError):
    """A bag that cannot be read at all (not MCAP), or a chunk that changed while it was read."""


@dataclass(frozen=True)
class TopicInfo:
    name: str
    type: str
    message_count: int
    serialization_format: str
    offered_qos_profiles: list
    type_description_hash: str


@dataclass
class BagMessage:
    """One recorded message; ``msg`` deserialises ``data`` on first use."""
    topic: str
    type: str
    log_time_ns: int  # receive time at the recorder (sim time if it ran on /clock)
    publish_time_ns: int  # source timestamp from the middleware, or the log time
    data: bytes  # CDR, encapsulation header included

    @functools.cached_property
    def msg(self):
        return deserialize_message(self.data, message_class(self.type))


class BagReader:
    """Open a bag directory or .mcap file for reading.

    >>> bag = BagReader("bags/run1")
    >>> bag.topics["/joint_states"].type
    'sensor_msgs/msg/JointState'
    >>> for m in bag.messages(["/joint_states"]):
    ...     print(m.log_time_ns, m.msg.position)
    >>> t, position = bag.series("/joint_states", "position")
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.damage: list[Damage] = []                           # parts skipped, every file
        self.problems: list[str] = []                            # data lost or damage found, for the user
        directory_metadata, problem = _directory_metadata(self.path)
        if problem:
            self.problems.append(problem)
        self.files = _mcap_files(self.path, directory_metadata)
        self._layouts: list[McapLayout] = []
        self._channels: list[dict[int, tuple[str, str]]] = []  # per file: channel id -> (topic, type)
        topics: dict[str, dict] = {}
        embedded: dict | None = None
        for file in self.files:
            try:
                found = layout(file)
            except NotMcapError as exc:
                raise CorruptBagError(str(exc)) from None
            self._layouts.append(found)
            if not found.indexed:
                self.problems.append(f"{file.name}: no summary that matches the file (the recording was cut "
                                     f"off?): read {found.message_count} messages by a linear scan; "
                                     "`cdpr bag reindex` rebuilds the index")
            self.damage.extend(found.damage)
            self.problems.extend(str(d) for d in found.damage)
            channels = {}
            for cid, ch in found.channels.items():
                schema = found.schemas.get(ch.schema_id)
                channels[cid] = (ch.topic, schema.name if schema is not None else "")
                entry = topics.setdefault(ch.topic, {
                    "type": channels[cid][1], "count": 0, "format": ch.message_encoding,
                    "qos": parse_profiles(ch.metadata.get("offered_qos_profiles")),
                    "hash": ch.metadata.get("topic_type_hash", "")})
                entry["count"] += found.counts.get(cid, 0)
            self._channels.append(channels)
            if embedded is None:
                embedded = _embedded_metadata_records(found.metadata)
        self.message_count = sum(f.message_count for f in self._layouts)
        starts = [f.start_time for f in self._layouts if f.message_count]
        self.start_time_ns: int | None = min(starts, default=None)
        self.end_time_ns: int | None = max((f.end_time for f in self._layouts if f.message_count), default=None)
        self.topics = {name: TopicInfo(name, e["type"], e["count"], e["format"], e["qos"], e["hash"])
                       for name, e in sorted(topics.items())}
        self.metadata = directory_metadata or embedded or {}

    @property
    def lost_messages(self) -> tuple[int, int]:
        """Messages lost in the skipped parts: ``(counted, parts whose loss is unknown)``."""
        return (sum(d.lost or 0 for d in self.damage), sum(1 for d in self.damage if d.lost is None))

    @property
    def duration_ns(self) -> int:
        return (self.end_time_ns - self.start_time_ns) if self.message_count else 0

    def messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[BagMessage]:
        """Messages in log-time order, optionally only ``topics`` and log times in [start_ns, end_ns)."""
        wanted = None
        if topics is not None:
            wanted = set(topics)
            unknown = wanted - set(self.topics)
            if unknown:
                raise ValueError(f"bag {self.path} has no topic {', '.join(sorted(unknown))}; "
                                 f"topics: {', '.join(self.topics) or '(none)'}")
        streams = [self._file_messages(i, wanted, start_ns, end_ns) for i in range(len(self.files))]
        merged = heapq.merge(*streams, key=lambda m: m.log_time_ns) if len(streams) > 1 else streams[0]
        if start_ns is not None or end_ns is not None:  # the count of a time range is not in the summary
            yield from merged
            return
        total = sum(info.message_count for name, info in self.topics.items() if wanted is None or name in wanted)
        yield from track(merged, total, f"reading {self.path.name}")

    def _file_messages(self, index: int, wanted, start_ns, end_ns) -> Iterator[BagMessage]:
        channels = self._channels[index]
        ids = None if wanted is None else {cid for cid, (topic, _) in channels.items() if topic in wanted}
        try:
            for message in self._layouts[index].messages(ids, start_ns, end_ns):
                topic, type_name = channels[message.channel_id]
                yield BagMessage(topic, type_name, message.log_time, message.publish_time, message.data)
        except ChunkError as exc:
            raise CorruptBagError(str(exc)) from exc

    def series(self, topic: str, *fields: str, stamp: str = "log") -> tuple[np.ndarray, ...]:
        """Time series of fields of one topic: ``(t, values_1, ...)`` as numpy arrays.

        ``t`` is in seconds: log time since the bag's start (float64 keeps ns resolution that way),
        or with ``stamp="header"`` the messages' ``header.stamp`` as is (sim time starts near 0).
        Fields are dotted paths (``"wrench.force.x"``); array fields give one row per message.
        """
        if stamp not in ("log", "header"):
            raise ValueError(f"stamp must be 'log' or 'header', got {stamp!r}")
        times, columns = [], [[] for _ in fields]
        for m in self.messages([topic]):
            msg = m.msg
            if stamp == "header":
                s = field_value(msg, "header.stamp")
                times.append(s.sec + 1e-9 * s.nanosec)
            else:
                times.append(1e-9 * (m.log_time_ns - self.start_time_ns))
            for column, path in zip(columns, fields):
                column.append(np.asarray(field_value(msg, path)))
        return (np.asarray(times, dtype=float), *(_stack(c, topic, p) for c, p in zip(columns, fields)))


def _mcap_files(path: Path, metadata: dict | None) -> list[Path]:
    if path.is_file() and path.suffix == ".mcap":
        return [path]
    if path.is_dir():
        if metadata and metadata.get("relative_file_paths"):
            files = [path / Path(p).name for p in metadata["relative_file_paths"]]
        else:
            files = sorted(path.glob("*.mcap"), key=split_order)
        missing = [f for f in files if not f.is_file()]
        if missing:
            raise FileNotFoundError(f"bag {path}: missing {', '.join(map(str, missing))} (listed in its "
                                    "metadata.yaml; `cdpr bag reindex` rebuilds it from the files present)")
        if files:
            return files
    raise FileNotFoundError(f"no bag at {path}: expected a bag directory with .mcap files or an .mcap file")


def _directory_metadata(path: Path) -> tuple[dict | None, str | None]:
    """A bag directory's metadata.yaml (rosbag2_bagfile_information) and, when it exists but cannot
    be used, why: it is then ignored (the .mcap files hold everything, and are read by their names),
    as a damaged index would be."""
    meta = path / "metadata.yaml" if path.is_dir() else None
    if meta is None or not meta.is_file():
        return None, None
    ignored = "; ignored: the bag's .mcap files are read by their names; `cdpr bag reindex` writes it again"
    try:
        data = load_yaml(meta, "bag metadata file")
    except YamlFileError as exc:            # names the file and the problem (encoding, YAML, nesting)
        return None, f"{exc}{ignored}"
    if data is None:
        return None, None                   # emptied: the files tell (issue 28)
    info = data.get("rosbag2_bagfile_information") if isinstance(data, dict) else None
    files = info.get("relative_file_paths") if isinstance(info, dict) else None
    if not isinstance(info, dict):
        why = "no rosbag2_bagfile_information mapping in it"
    elif files is not None and not (isinstance(files, list) and all(isinstance(f, str) for f in files)):
        why = "relative_file_paths is not a list of file names"
    else:
        return info, None
    return None, f"{meta}: cannot be used ({why}){ignored}"


def _embedded_metadata_records(records) -> dict | None:
    """The rosbag2 metadata a file carries in its metadata record; None when it has none or the
    record is damaged (it lies outside the chunks, under no CRC, and only repeats what the
    chunks tell)."""
    for record in records:
        if record.name == "rosbag2" and "serialized_metadata" in record.metadata:
            try:
                metadata = yaml.safe_load(record.metadata["serialized_metadata"])
            except (yaml.YAMLError, RecursionError):
                return None
            return metadata if isinstance(metadata, dict) else None
    return None


def _stack(values: list, topic: str, path: str) -> np.ndarray:
    try:
        return np.stack(values) if values else np.empty(0)
    except ValueError:
        raise ValueError(f"{topic} {path}: array length changes between messages; "
                         "iterate with messages() instead") from None

"""BagWriterProcess: a :class:`~cdpr_tools.bag.writer.BagWriter` in a child process, fed in batches.

The bag recorder composed with a control loop receives its messages on the loop's thread. Writing
them there (MCAP records, chunk buffer, message indexes, statistics, compression, file IO: about
11 us a message, 20 messages a 1 ms period) doubled the loop's CPU time; that work holds the GIL, so
a thread would not help either. So the recorder only encodes each message (:mod:`.encode`) and
appends ``(topic index, log time, bytes)`` to a queue, and every ``batch`` messages (and when
the recorder's timer calls :meth:`BagWriterProcess.send`) the queue goes to a child process as
one pickled list in one pipe write. The child (``python -m cdpr_tools.bag.writer_process``)
writes them with a BagWriter (:meth:`~cdpr_tools.bag.writer.BagWriter.write_serialized`), the
project's one bag writer, on the other core.

Closing sends what is queued, asks the child to close the bag (summary, metadata.yaml) and waits for
it. If the parent dies without closing (SIGKILL, a crash), the child reads end-of-file and closes
the bag just the same, so the bag is complete up to the last batch sent (a BagWriter in a killed
process loses its chunk in progress and its summary). The child ignores SIGINT and SIGTERM, which a
terminal or a launcher sends to the whole process group: it ends when its parent does, and a
recording stopped by Ctrl-C is still closed by the parent. When idle the child puts the chunk in
progress on disk after ``flush_interval`` seconds, so a long pause loses nothing either.

A write that fails in the child (disk full: :class:`~cdpr_tools.bag.writer.BagWriteError`) ends
the recording, not the loop: the child answers why and how many messages are on disk, and exits;
the parent's next pipe write fails, it reads that answer (:attr:`BagWriterProcess.failed`) and goes
on without recording. After :meth:`BagWriterProcess.close`, :attr:`~BagWriterProcess.message_count`
is the count the child reports on disk, never what was merely sent.

Frames on the pipe: one kind byte, a uint32 length, then the payload: ``O`` open (pickled
arguments; the child answers one JSON line on stdout), ``T`` a topic (pickled ``add_topic``
arguments, topics numbered in order), ``M`` messages (a pickled list of ``(topic index, log time
[ns], CDR bytes, exact)``; ``exact``: the bytes are the encoding alone, no length walk needed),
``F`` flush, ``C`` close (the child answers a JSON line with the message count and exits).
"""
from __future__ import annotations

import atexit
import builtins
import fcntl
import json
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import threading
from collections import deque
from pathlib import Path
from typing import Any

BATCH = 256            # messages per pipe write (about 12 periods of the closed loop)
PIPE_SIZE = 1 << 20    # bytes the pipe buffers before a write blocks (Linux's default limit)
_F_SETPIPE_SZ = 1031   # fcntl command (Linux)
_FRAME = struct.Struct("<cI")


class BagWriterProcess:
    """Write a bag from a child process; same bag, arguments and ``path`` as :class:`BagWriter`.

    >>> bag = BagWriterProcess("bags/run1", compression="zstd")
    >>> i = bag.add_topic("/chatter", "std_msgs/msg/String")
    >>> bag.put((i, log_time_ns, serialize(String(data="hi")), True))
    >>> bag.close()
    """

    def __init__(self, path: str | os.PathLike, *, compression: str = "zstd", chunk_size: int = 1 << 20,
                 flush_interval: float = 1.0, batch: int = BATCH, max_bag_size: int = 0, max_bag_duration: float = 0.0):
        self.batch = batch
        # the parent's sys.path: the child imports the same cdpr_tools, however the parent found it
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
        self._proc = subprocess.Popen([sys.executable, "-m", "cdpr_tools.bag.writer_process"],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, bufsize=0, env=env)
        self._pipe = self._proc.stdin
        try:
            fcntl.fcntl(self._pipe.fileno(), _F_SETPIPE_SZ, PIPE_SIZE)
        except OSError:
            pass                                  # a smaller pipe only means earlier blocking
        self._lock = threading.Lock()
        self.queue: deque = deque()             # what put() appends and send() hands over
        self._sent = 0
        self._closed = False
        self._final: dict | None = None           # the child's last answer (it wrote what it could)
        self.failed: str | None = None            # why the child stopped taking messages, if it did
        self.topics: dict[str, str] = {}          # topic -> type, in the order of their indexes
        self._frame(b"O", pickle.dumps({"path": str(path), "compression": compression, "chunk_size": chunk_size,
                                        "flush_interval": flush_interval, "max_bag_size": max_bag_size,
                                        "max_bag_duration": max_bag_duration}))
        reply = self._reply()
        if "error" in reply:
            self._proc.wait()
            raise _exception(reply["error"])(reply["message"])
        self.path = Path(reply["path"])
        atexit.register(self.close)              # the queue still goes out if nobody closes

    # -- the parent's side ---------------------------------------------------------------------
    def add_topic(self, topic: str, type_name: str, qos: Any = None, type_description_hash: str | None = None) -> int:
        """Declare a topic (arguments as :meth:`BagWriter.add_topic`); returns its index for :meth:`put`.
        An unknown type raises here (LookupError), not in the child."""
        from cdpr_tools.bag.schema import message_definition, type_hash
        from cdpr_tools.bag.writer import _profiles
        with self._lock:
            if topic in self.topics:
                if self.topics[topic] != type_name:
                    raise ValueError(f"topic {topic} is recorded as {self.topics[topic]}, not {type_name}")
                return list(self.topics).index(topic)
            message_definition(type_name)
            digest = type_hash(type_name) if type_description_hash is None else type_description_hash
            self._send_locked()                   # messages queued before it keep their place
            self._frame(b"T", pickle.dumps((topic, type_name, _profiles(qos), digest)))
            self.topics[topic] = type_name
            return len(self.topics) - 1

    def put(self, item: tuple[int, int, bytes, bool]) -> None:
        """Queue ``(topic index, log time [ns], CDR bytes, exact)``; sends every ``batch`` items.
        Safe from any thread (deque appends are atomic; sending takes the lock)."""
        queue = self.queue
        queue.append(item)
        if len(queue) >= self.batch:
            self.send()

    def send(self) -> None:
        """Hand what is queued to the child now (the recorder's timer calls this every 0.1 s)."""
        with self._lock:
            self._send_locked()

    def _send_locked(self) -> None:
        queue = self.queue
        n = len(queue)
        if not n or self._closed:
            return
        items = [queue.popleft() for _ in range(n)]
        self._frame(b"M", pickle.dumps(items, protocol=pickle.HIGHEST_PROTOCOL))
        self._sent += n

    def flush(self) -> None:
        """Send the queue and have the child put its chunk in progress on disk."""
        with self._lock:
            self._send_locked()
            self._frame(b"F", b"")

    @property
    def pid(self) -> int:
        """Process id of the writer child (to account for its CPU time)."""
        return self._proc.pid

    @property
    def message_count(self) -> int:
        """Messages taken so far (sent to the child or queued); after :meth:`close`, the messages
        the bag holds on disk."""
        if self._closed and self._final is not None:
            return self._final["messages"]
        return self._sent + len(self.queue)

    def close(self) -> None:
        """Send the queue, have the child finish the bag, wait for it; safe to call twice."""
        with self._lock:
            if self._closed:
                return
            self._send_locked()
            self._frame(b"C", b"")
            self._closed = True
        atexit.unregister(self.close)
        try:
            self._pipe.close()
        except OSError:
            pass
        self._last_reply()
        self._proc.wait()
        self._proc.stdout.close()

    def _last_reply(self) -> dict:
        """The child's closing answer (read once): messages on disk, and why it failed if it did.
        A child that ended without one (killed) leaves the count to a reading of the file."""
        if self._final is None:
            reply = self._reply()
            if "messages" not in reply:
                reply["messages"] = _count_on_disk(self.path)
            if "error" in reply:
                self.failed = reply["message"]
            self._final = reply
        return self._final

    def _frame(self, kind: bytes, payload: bytes) -> None:
        if self.failed is not None:
            return
        try:
            data = memoryview(_FRAME.pack(kind, len(payload)) + payload)
            while data:
                data = data[self._pipe.write(data):]
        except (OSError, ValueError) as exc:      # the child died: the recording stops, the loop goes on
            self.failed = f"bag writer process ended ({exc}); messages are no longer recorded"
            self._last_reply()                    # its reason, if it gave one (it has exited)

    def _reply(self) -> dict:
        line = self._proc.stdout.readline()
        if not line:
            return {"error": "RuntimeError", "message": f"bag writer process exited with {self._proc.wait()}"}
        return json.loads(line)


def _exception(name: str) -> type:
    """The built-in exception class the child named (OSError and its kinds included)."""
    cls = getattr(builtins, name, None)
    return cls if isinstance(cls, type) and issubclass(cls, Exception) else RuntimeError


def _count_on_disk(path: Path) -> int:
    from cdpr_tools.bag.reader import BagReader
    try:
        return BagReader(path).message_count
    except Exception:                              # noqa: BLE001 - nothing readable: nothing on disk
        return 0


# -- the child's side --------------------------------------------------------------------------
def _read(fd: int, n: int) -> bytes | None:
    chunks, left = [], n
    while left:
        chunk = os.read(fd, left)
        if not chunk:
            return None
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def _answer(reply: dict) -> None:
    try:
        sys.stdout.write(json.dumps(reply) + "\n")
        sys.stdout.flush()
    except OSError:
        pass                                       # the parent is gone and reads no answer


def main() -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # the parent closes the bag, or end-of-file does
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    from cdpr_tools.bag.writer import BagWriteError, BagWriter
    fd = sys.stdin.fileno()
    writer = None
    topics: list[str] = []                         # by index
    try:
        while True:
            if writer is not None and not select.select([fd], [], [], writer.flush_interval)[0]:
                writer.flush_due()                 # idle: the chunk in progress goes to disk
                continue
            head = _read(fd, _FRAME.size)
            if head is None:
                break                              # the parent is gone: close the bag
            kind, length = _FRAME.unpack(head)
            payload = _read(fd, length) if length else b""
            if payload is None:
                break
            if kind == b"M":
                writer.write_serialized([(topics[i], t, data, exact) for i, t, data, exact in pickle.loads(payload)])
            elif kind == b"T":
                topic, type_name, profiles, digest = pickle.loads(payload)
                writer.add_topic(topic, type_name, profiles, digest)
                topics.append(topic)
            elif kind == b"O":
                args = pickle.loads(payload)
                try:
                    writer = BagWriter(args.pop("path"), **args)
                except (OSError, ValueError, LookupError) as exc:   # exists, cannot be created, disk full
                    kind_name = "OSError" if isinstance(exc, BagWriteError) else type(exc).__name__
                    _answer({"error": kind_name, "message": str(exc)})
                    return 1
                _answer({"path": str(writer.path)})
            elif kind == b"F":
                writer.flush()
            elif kind == b"C":
                break
        if writer is not None:
            writer.close()
            _answer({"messages": writer.message_count})
    except BagWriteError as exc:                   # disk full: the bag is cut at its last chunk
        _answer({"error": "OSError", "message": str(exc), "messages": writer.messages_on_disk})
        return 1
    except BaseException as exc:
        if writer is not None:
            writer.close()
        _answer({"error": type(exc).__name__, "message": f"bag writer process: {exc!r}"})
        raise
    return 0


if __name__ == "__main__":
    sys.exit(main())

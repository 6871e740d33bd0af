"""A disk that fills while recording (issue 28): the writer stops at its last complete chunk, the
count printed is what the bag holds on disk, the exit is non-zero, no traceback. And the usage
errors of `cdpr bag record` and `cdpr bag play` are one-line errors with exit 2.

Three ways to fill the disk: a file object that fails with ENOSPC after N bytes (BagWriter's
``opener`` seam), a file size limit (RLIMIT_FSIZE: writes fail with EFBIG) on a `cdpr` process,
and a real 1 MiB tmpfs where ``mount`` is allowed."""
import errno
import io
import re
import resource
import signal
import subprocess
import sys
import threading

import pytest
import yaml
from sensor_msgs.msg import JointState

from cdpr_test_nodes.graph import Spinner, subprocess_env, wait_for
from cdpr_test_nodes.talker import Talker
from cdpr_tools.bag import BagReader, BagWriter
from cdpr_tools.bag.recovery import reindex
from cdpr_tools.bag.writer import BagWriteError
from cdpr_tools.cli import main as cdpr
from rclpy.parameter import Parameter

CHUNK = 4096


class FullDisk(io.RawIOBase):
    """A file that takes ``room`` bytes, then fails every write with ENOSPC (a partial write first)."""

    def __init__(self, path, room: int):
        self._file = open(path, "wb", buffering=0)
        self.room = room

    def writable(self) -> bool:
        return True

    def write(self, data) -> int:
        if self.room <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        n = self._file.write(bytes(data)[:self.room])
        self.room -= n
        return n

    def seek(self, *args) -> int:
        return self._file.seek(*args)

    def tell(self) -> int:
        return self._file.tell()

    def close(self) -> None:
        self._file.close()
        super().close()


def fill(path, room: int) -> tuple[int, BagWriter, BagWriteError]:
    """Write JointStates into a bag on a disk with ``room`` bytes until it fails; (written, bag, error)."""
    bag = BagWriter(path, chunk_size=CHUNK, opener=lambda p, mode: io.BufferedWriter(FullDisk(p, room)))
    for k in range(100_000):
        try:
            bag.write("/winch/state", None, JointState(position=[float(k)] * 8), 1_000_000 * (k + 1))
        except BagWriteError as exc:
            return k, bag, exc
    raise AssertionError("the disk never filled")


@pytest.mark.parametrize("room", [20_000, 77_777, 150_001])
def test_writer_stops_at_its_last_complete_chunk_and_counts_what_is_on_disk(tmp_path, room):
    written, bag, error = fill(tmp_path / "run", room)
    assert "No space left on device" in str(error) and str(bag.mcap_path) in str(error)
    assert f"{bag.messages_on_disk} messages are on disk" in str(error)
    size = (tmp_path / "run" / "run_0.mcap").stat().st_size
    assert size <= room                                                 # cut back, not grown
    on_disk = BagReader(tmp_path / "run")
    assert 0 < on_disk.message_count == bag.messages_on_disk < written
    # the file ends at a record boundary: nothing half-written to skip, only the missing footer
    assert [(d.start, d.end) for d in on_disk.damage] == [(size, size)]
    # every message up to the last complete chunk, in order
    assert [m.msg.position[0] for m in on_disk.messages()] == [float(k) for k in range(on_disk.message_count)]
    info = yaml.safe_load((tmp_path / "run" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["message_count"] == on_disk.message_count
    with pytest.raises(BagWriteError):                                  # stopped for good
        bag.write("/winch/state", None, JointState(position=[0.0]), 1)
    bag.close()                                                          # and closing is quiet
    reindex(tmp_path / "run")                                            # with room again: whole
    assert BagReader(tmp_path / "run").message_count == on_disk.message_count


def test_a_disk_full_while_closing_keeps_the_chunks_before(tmp_path):
    """The last chunk and the summary no longer fit: the bag ends at its last flushed chunk."""
    def write_all(bag) -> None:
        for k in range(300):
            bag.write("/winch/state", None, JointState(position=[float(k)] * 8), 1_000_000 * (k + 1))
    with BagWriter(tmp_path / "whole.mcap", chunk_size=CHUNK) as bag:
        write_all(bag)
    room = (tmp_path / "whole.mcap").stat().st_size - 200
    bag = BagWriter(tmp_path / "run", chunk_size=CHUNK,
                    opener=lambda p, mode: io.BufferedWriter(FullDisk(p, room)))
    write_all(bag)
    with pytest.raises(BagWriteError, match="No space left"):
        bag.close()
    on_disk = BagReader(tmp_path / "run")
    assert 0 < on_disk.message_count == bag.messages_on_disk < 300
    assert [m.msg.position[0] for m in on_disk.messages()] == [float(k) for k in range(on_disk.message_count)]
    size = (tmp_path / "run" / "run_0.mcap").stat().st_size
    assert size <= room and [(d.start, d.end) for d in on_disk.damage] == [(size, size)]


def test_a_disk_full_before_the_header_fails_at_open(tmp_path):
    # and leaves nothing behind (issue 28: an empty bag directory stayed, and the same name was then
    # refused as existing), also directories it made on the way and a single-file bag
    for name in ("run", "new/dirs/run", "run.mcap"):
        with pytest.raises(BagWriteError, match="No space left"):
            BagWriter(tmp_path / name, opener=lambda p, mode: io.BufferedWriter(FullDisk(p, 5)))
        assert list(tmp_path.iterdir()) == []
    with BagWriter(tmp_path / "run") as bag:                           # the name is free again
        bag.write("/winch/state", None, JointState(position=[1.0]), 1)
    assert BagReader(tmp_path / "run").message_count == 1


# -- `cdpr bag record` and `cdpr launch --record` on a full disk ----------------------------------
PAYLOAD = "x" * 1000     # 1 kB at 200 Hz: the recorder's 1 s chunks are about 200 kB (uncompressed)


@pytest.fixture
def talker():
    spinner = Spinner()
    spinner.add(Talker, namespace="/df", parameter_overrides=[
        Parameter("rate", value=200.0), Parameter("greeting", value=PAYLOAD)])
    yield spinner
    spinner.close()


@pytest.fixture
def tmpfs(tmp_path):
    mount = tmp_path / "small_disk"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"mount -t tmpfs refused here ({done.stderr.strip() or done.returncode}); "
                    "the RLIMIT_FSIZE tests cover a full disk without it")
    yield mount
    subprocess.run(["umount", "-l", str(mount)], check=False)


def file_size_limit(limit: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


class Cdpr:
    """A `cdpr` subprocess whose output is read by a thread (so a full pipe never blocks it)."""

    def __init__(self, args, **popen):
        self.proc = subprocess.Popen([sys.executable, "-m", "cdpr_tools.cli", *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, env=subprocess_env(), **popen)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=lambda: self.lines.extend(self.proc.stdout), daemon=True)
        self._reader.start()

    @property
    def output(self) -> str:
        return "".join(self.lines)

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGINT)
        code = self.proc.wait(60)
        self._reader.join(10)
        return code

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


@pytest.fixture
def run_cdpr():
    started: list[Cdpr] = []

    def start(args, **popen) -> Cdpr:
        started.append(Cdpr(args, **popen))
        return started[-1]
    yield start
    for process in started:
        process.kill()


def record_until_full(run_cdpr, bag, **popen) -> tuple[int, str]:
    process = run_cdpr(["bag", "record", "-a", "-o", str(bag), "--compression", "none"], **popen)
    wait_for(lambda: "recording stopped" in process.output, timeout=90, what="the disk to fill")
    return process.stop(), process.output


def check_count_is_on_disk(output: str, bag, pattern: str) -> int:
    printed = int(re.search(pattern, output).group(1))
    assert printed == BagReader(bag).message_count > 0, output
    assert "Traceback" not in output, output
    return printed


def test_bag_record_on_a_full_tmpfs_exits_non_zero_with_the_count_on_disk(talker, tmpfs, run_cdpr):
    code, output = record_until_full(run_cdpr, tmpfs / "run")
    assert code == 1, output
    assert "No space left on device" in output
    check_count_is_on_disk(output, tmpfs / "run", rf"bag {tmpfs / 'run'}: (\d+) messages")


def test_bag_record_over_a_file_size_limit_exits_non_zero_with_the_count_on_disk(talker, tmp_path, run_cdpr):
    code, output = record_until_full(run_cdpr, tmp_path / "run", preexec_fn=file_size_limit(600_000))
    assert code == 1, output
    assert "File too large" in output and "cdpr bag record: error:" in output
    check_count_is_on_disk(output, tmp_path / "run", rf"bag {tmp_path / 'run'}: (\d+) messages")


LAUNCH = f"""
launch:
  - node:
      pkg: cdpr_test_nodes
      exec: talker
      namespace: /df_launch
      param:
        - {{name: rate, value: 200.0}}
        - {{name: greeting, value: {PAYLOAD}}}
"""


def test_launch_record_over_a_file_size_limit_exits_non_zero_with_the_count_on_disk(tmp_path, run_cdpr):
    (tmp_path / "graph.yaml").write_text(LAUNCH)
    process = run_cdpr(["launch", str(tmp_path / "graph.yaml"), "--record", str(tmp_path / "run"),
                        "--record-compression", "none"],
                       preexec_fn=file_size_limit(600_000))
    wait_for(lambda: "recording stopped" in process.output, timeout=90, what="the disk to fill")
    assert process.stop() == 1, process.output
    assert "[launch] stopped with errors: recording:" in process.output
    check_count_is_on_disk(process.output, tmp_path / "run", rf"\[launch\] bag {tmp_path / 'run'}: (\d+) messages")


# -- usage errors ---------------------------------------------------------------------------------
def test_bag_record_into_a_directory_that_cannot_be_created_is_a_one_line_error(tmp_path, capsys):
    (tmp_path / "a_file").write_text("")
    assert cdpr(["bag", "record", "-a", "-o", str(tmp_path / "a_file" / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("cdpr bag record: error: cannot create the bag")
    assert str(tmp_path / "a_file" / "run") in err[0] and "Traceback" not in err[0]


@pytest.mark.parametrize("args", [["record", "-a", "--stop-after", "-1"], ["record", "-a", "--stop", "nan"],
                                  ["play", "BAG", "-r", "nan"], ["play", "BAG", "-r", "inf"],
                                  ["play", "BAG", "-r", "0"], ["play", "BAG", "-r", "-2"],
                                  ["play", "BAG", "--start-offset", "-1"], ["play", "BAG", "--clock", "nan"]])
def test_bad_numbers_are_refused_with_exit_2(args, capsys):
    with pytest.raises(SystemExit) as exit_:
        cdpr(["bag", *args])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    option = next(a for a in args if a.startswith("-"))
    assert "error: argument" in err and option.split("=")[0][:7] in err and "Traceback" not in err

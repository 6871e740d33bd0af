"""Progress of long commands: a line per tenth into logs, one rewritten line on a terminal, silent
unless the cdpr command (or the caller) turns it on."""
import io

import pytest

from cdpr_tools import progress
from cdpr_tools.bag import BagReader, BagWriter


class Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.fixture
def enabled():
    progress.enable()
    yield
    progress.enable(False)


def test_a_line_per_tenth_into_a_log(enabled):
    log = io.StringIO()
    p = progress.Progress("work", stream=log)
    for k in range(1, 101):
        p.update(k / 100, f"item {k}")
    p.done()
    lines = log.getvalue().splitlines()
    assert lines[0] == "work:   1.0 %  item 1" and lines[1] == "work:  10.0 %  item 10"
    assert lines[-1] == "work: 100.0 %  item 100" and len(lines) == 11  # the start, then each tenth


def test_one_rewritten_line_on_a_terminal(enabled, monkeypatch):
    monkeypatch.setattr(progress, "MIN_INTERVAL", 0.0)
    tty = Terminal()
    p = progress.Progress("work", stream=tty)
    for k in range(5):
        p.update(k / 4)
    p.done()
    text = tty.getvalue()
    assert text.count("\r\x1b[K") == 6 and text.count("\n") == 1 and text.endswith("work: 100.0 %\n")


def test_silent_unless_enabled(capsys):
    assert list(progress.track(range(5), 5, "quiet")) == [0, 1, 2, 3, 4]
    progress.Progress("quiet").update(0.5)
    assert capsys.readouterr().err == ""


def test_reading_a_bag_shows_progress(enabled, tmp_path, capsys):
    from std_msgs.msg import Int32

    with BagWriter(tmp_path / "bag") as bag:
        for k in range(50):
            bag.write("/n", None, Int32(data=k), k * 1_000_000)
    assert [m.msg.data for m in BagReader(tmp_path / "bag").messages()] == list(range(50))
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("reading bag:") and err[-1] == "reading bag: 100.0 %"

"""Progress.stop: failed work ends its progress without claiming 100 % (used by `cdpr program run`)."""
import io

import pytest

from cdpr_tools import progress


class Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.fixture
def enabled(monkeypatch):
    monkeypatch.setattr(progress, "MIN_INTERVAL", 0.0)
    progress.enable()
    yield
    progress.enable(False)


def test_stop_closes_the_terminal_line_without_claiming_completion(enabled):
    tty = Terminal()
    p = progress.Progress("program 'x'", stream=tty)
    p.update(0.4, "line 3")
    p.stop()
    assert tty.getvalue() == "\r\x1b[Kprogram 'x':  40.0 %  line 3\n"
    p.stop()                                    # once closed, nothing more
    assert tty.getvalue().count("\n") == 1


def test_stop_into_a_log_adds_nothing(enabled):
    log = io.StringIO()
    p = progress.Progress("program 'x'", stream=log)
    p.update(0.4, "line 3")
    p.stop()
    assert log.getvalue() == "program 'x':  40.0 %  line 3\n"


def test_stop_before_any_update_writes_nothing(enabled):
    tty = Terminal()
    progress.Progress("program 'x'", stream=tty).stop()
    assert tty.getvalue() == ""

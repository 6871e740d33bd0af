"""The composed graph's publication mode for observers (cdpr_tools.launch.observers_published_asynchronously)."""
import os

import pytest

from cdpr_tools.launch import PUBLICATION_MODE, observers_published_asynchronously


@pytest.fixture
def no_mode(monkeypatch):
    monkeypatch.delenv(PUBLICATION_MODE, raising=False)


def test_asynchronous_while_the_composed_graph_is_built_and_restored_after(no_mode):
    with observers_published_asynchronously(True):
        assert os.environ[PUBLICATION_MODE] == "ASYNCHRONOUS"
    assert PUBLICATION_MODE not in os.environ


def test_restored_when_building_fails(no_mode):
    with pytest.raises(RuntimeError):
        with observers_published_asynchronously(True):
            raise RuntimeError("a node failed to start")
    assert PUBLICATION_MODE not in os.environ


def test_a_mode_the_user_set_is_kept(monkeypatch):
    monkeypatch.setenv(PUBLICATION_MODE, "SYNCHRONOUS")
    with observers_published_asynchronously(True):
        assert os.environ[PUBLICATION_MODE] == "SYNCHRONOUS"
    assert os.environ[PUBLICATION_MODE] == "SYNCHRONOUS"


def test_unchanged_when_the_loop_itself_goes_over_dds(no_mode):
    with observers_published_asynchronously(False):
        assert PUBLICATION_MODE not in os.environ

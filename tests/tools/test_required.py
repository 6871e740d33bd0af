"""A missing optional module skips a test module on a developer machine and fails it in CI."""
import pytest

from required import import_or_skip


def test_missing_module_fails_in_ci(monkeypatch):
    monkeypatch.setenv("CI", "true")
    with pytest.raises(ImportError):
        import_or_skip("cdpr_no_such_module")


def test_missing_module_skips_outside_ci(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception):
        import_or_skip("cdpr_no_such_module")


def test_present_module_is_returned_either_way(monkeypatch):
    monkeypatch.setenv("CI", "true")
    assert import_or_skip("numpy").__name__ == "numpy"

"""Optional imports of the test suite that are not optional in CI.

``pytest.importorskip`` turns a missing or broken ROS 2 (rclpy, message packages) or numba into a
skip, which on a developer machine without ROS is what one wants and in CI would hide a broken
install behind a green run. CI sets ``CI=true``: there a missing module fails the test module.
"""
import importlib
import os

import pytest


def import_or_skip(name: str):
    """The module ``name``; skip without it, except in CI (CI=true) where its ImportError fails."""
    if os.environ.get("CI", "").strip().lower() in ("true", "1", "yes"):
        return importlib.import_module(name)
    return pytest.importorskip(name)

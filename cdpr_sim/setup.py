"""Build script: colcon (ament_python) runs it; the package metadata and entry points are in pyproject.toml.

It adds what ROS 2 tools look for under the install prefix: the ament index marker, package.xml and
the share files (``share/cdpr_sim/...``, found by ``ament_index_python`` and ``$(find-pkg-share)``).
"""
import sys
from glob import glob
from pathlib import Path

from setuptools import setup

PACKAGE = "cdpr_sim"
SHARE = ()  # (folder, pattern) of the Python package to share/<package>/<folder>: none here
HERE = Path(__file__).resolve().parent


def data_files() -> list:
    # An editable install (pip install -e) reads the share files from the source tree
    # (cdpr_tools.share); a copy in the environment would go stale with the first edit.
    if "editable_wheel" in sys.argv:
        return []
    files = [("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
             (f"share/{PACKAGE}", ["package.xml"])]
    for folder, pattern in SHARE:
        files.append((f"share/{PACKAGE}/{folder}", sorted(glob(f"{PACKAGE}/{folder}/{pattern}", root_dir=HERE))))
    return files


setup(data_files=data_files())

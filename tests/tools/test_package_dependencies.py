"""Every import of a package is declared in its package.xml, and every declaration is imported.

An import walk (ast) of each ament_python package's sources: the third-party top-level modules it
imports map to rosdep keys (ROS packages by their name, Python packages by rosdistro's python.yaml
key) that must be its ``exec_depend``s, so that ``rosdep install`` on a full ROS 2 install leaves
nodes that import; modules without a rosdep key must be named in the package.xml's pip comment and
pinned in requirements.txt. docs/tools.md's list of node executables matches the entry points.
"""
from __future__ import annotations

import ast
import re
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("cdpr_control", "cdpr_sim", "cdpr_tools")
# Python modules with a rosdep key (rosdistro rosdep/python.yaml)
ROSDEP_KEYS = {"numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml",
               "matplotlib": "python3-matplotlib", "mpl_toolkits": "python3-matplotlib",
               "numba": "python3-numba", "pybullet": "python3-pybullet-pip",
               "qpsolvers": "python3-qpsolvers-pip"}
# Python modules without one: module -> the PyPI distribution pinned in requirements.txt
PIP_ONLY = {"ruckig": "ruckig", "daqp": "daqp", "proxsuite": "proxsuite", "control": "control",
            "mcap": "mcap", "foxglove": "foxglove-sdk", "zstandard": "zstandard", "lz4": "lz4"}


def imported_modules(package: str) -> set[str]:
    """Top-level modules the package imports, less the standard library and the package itself."""
    found = set()
    for path in (ROOT / package / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                found.update(a.name.split(".")[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                found.add(node.module.split(".")[0])
    return found - set(sys.stdlib_module_names) - {package, "__future__"}


def manifest(package: str) -> tuple[set[str], str]:
    """(exec_depend keys, the text of its comments) of a package.xml."""
    text = (ROOT / package / "package.xml").read_text(encoding="utf-8")
    keys = {e.text.strip() for e in ET.fromstring(text).iter("exec_depend")}
    return keys, " ".join(re.findall(r"<!--(.*?)-->", text, re.S))


@pytest.mark.parametrize("package", PACKAGES)
def test_every_import_is_declared_and_every_declaration_imported(package):
    modules = imported_modules(package)
    declared, comments = manifest(package)
    needed = {ROSDEP_KEYS.get(m, m) for m in modules if m not in PIP_ONLY}
    assert not needed - declared, f"{package}/package.xml lacks exec_depend {sorted(needed - declared)}"
    assert not declared - needed, f"{package}/package.xml declares what it does not import: {sorted(declared - needed)}"
    pip = {m for m in modules if m in PIP_ONLY}
    unnamed = [PIP_ONLY[m] for m in pip if not re.search(rf"\b{re.escape(PIP_ONLY[m])}\b", comments)]
    assert not unnamed, f"{package}/package.xml: name the pip-only {unnamed} in its comment"


def test_pip_only_modules_are_pinned():
    pinned = {line.split("==")[0].strip().lower() for line in (ROOT / "requirements.txt").read_text().splitlines()
              if "==" in line and not line.startswith("#")}
    assert set(PIP_ONLY.values()) <= pinned, set(PIP_ONLY.values()) - pinned


def test_docs_list_every_node_executable():
    text = (ROOT / "docs" / "tools.md").read_text(encoding="utf-8")
    start = text.index("Node executables")
    listing = text[start:text.index("Share files:", start)]
    for package in PACKAGES:
        scripts = tomllib.loads((ROOT / package / "pyproject.toml").read_text())["project"]["scripts"]
        for name in scripts:
            assert f"`{name}`" in listing, f"docs/tools.md does not list {package}'s executable {name}"

"""The tree is a ROS 2 workspace: package.xml (format 3, ament_python), node executables, share files
found through ament_index_python after a colcon build against the pip-installed ROS 2 wheels."""
import os
import re
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("cdpr_control", "cdpr_sim", "cdpr_tools")
SHARE_FILES = {
    "cdpr_control": ("package.xml", "params/ipanema3_mini.yaml", "params/ipanema3.yaml", "robots/ipanema3_mini.yaml",
                     "programs/cuboid_mini.gcode"),
    "cdpr_sim": ("package.xml",),
    "cdpr_tools": ("package.xml", "graphs/closed_loop.yaml", "layouts/cdpr.json"),
}


def scripts(package: str) -> dict[str, str]:
    return tomllib.loads((ROOT / package / "pyproject.toml").read_text())["project"]["scripts"]


@pytest.mark.parametrize("package", PACKAGES)
def test_package_xml_is_format_3_ament_python(package):
    root = ET.parse(ROOT / package / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == package
    assert root.find("export").findtext("build_type") == "ament_python"
    assert (ROOT / package / "resource" / package).is_file()  # the ament index marker setup.py installs
    depends = {e.text for e in root.iter("exec_depend")}
    assert {"rclpy", "cdpr_msgs"} <= depends
    assert tomllib.loads((ROOT / package / "pyproject.toml").read_text())["project"]["name"] == package


@pytest.mark.parametrize("package", ["cdpr_control", "cdpr_sim"])
def test_every_node_module_has_an_executable_of_its_name(package):
    nodes = sorted(p.stem for p in (ROOT / package / package / "nodes").glob("*.py")
                   if re.search(r"^def main\(", p.read_text(), re.M))
    declared = scripts(package)
    assert sorted(declared) == nodes
    for name, target in declared.items():  # the convention cdpr launch falls back to
        assert target == f"{package}.nodes.{name}:main"


def test_colcon_build_installs_executables_and_share_files_found_by_ament_index(tmp_path):
    """colcon build of the Python packages into a temporary directory; cdpr_msgs (CMake, about a
    minute) comes from the environment, where scripts/setup.sh built it with the same CMakeLists."""
    colcon = Path(sys.executable).with_name("colcon")
    env = {**os.environ, "AMENT_PREFIX_PATH": sys.prefix,
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    run = subprocess.run([str(colcon), "--log-base", str(tmp_path / "log"), "build",
                          "--base-paths", *(str(ROOT / p) for p in PACKAGES),
                          "--build-base", str(tmp_path / "build"), "--install-base", str(tmp_path / "install")],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert all(f"Finished <<< {p}" in run.stdout for p in PACKAGES)
    install = tmp_path / "install"
    for package in PACKAGES:
        lib = install / package / "lib" / package
        assert sorted(p.name for p in lib.iterdir()) == sorted(scripts(package))  # where ros2 run looks
        assert all(os.access(p, os.X_OK) for p in lib.iterdir())
    assert not list(ROOT.glob("cdpr_*/*.egg-info")) and not (ROOT / "cdpr_control" / "build").exists()

    # a fresh interpreter that sees only the install (as after `source install/setup.bash`)
    site = [str(next((install / p / "lib").glob("python3*/site-packages"))) for p in PACKAGES]
    probe = f"""
import json, sys
from ament_index_python.packages import get_package_share_directory
from cdpr_tools.share import package_share
from cdpr_tools.launch_file import load_launch_file
import cdpr_tools
shares = {{p: get_package_share_directory(p) for p in {PACKAGES!r}}}
assert all(str(package_share(p)) == s for p, s in shares.items())
graph = load_launch_file(package_share("cdpr_tools") / "graphs" / "closed_loop.yaml")
print(json.dumps({{"shares": shares, "module": cdpr_tools.__file__, "params": graph.nodes[1].parameters[0]}}))
"""
    env = {**os.environ, "AMENT_PREFIX_PATH": os.pathsep.join([*(str(install / p) for p in PACKAGES), sys.prefix]),
           "PYTHONPATH": os.pathsep.join(site)}
    probe_run = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert probe_run.returncode == 0, probe_run.stderr
    import json
    found = json.loads(probe_run.stdout.strip().splitlines()[-1])
    assert found["module"].startswith(str(install))  # not the source tree
    for package, files in SHARE_FILES.items():
        share = Path(found["shares"][package])
        assert share == install / package / "share" / package
        for name in files:
            assert (share / name).is_file(), name
    assert found["params"] == str(install / "cdpr_control" / "share" / "cdpr_control" / "params" / "ipanema3_mini.yaml")

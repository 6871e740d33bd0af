"""Importing the project changes no message class (issue 24, item 5): after every module of
cdpr_control, cdpr_sim and cdpr_tools is imported, the default instance of every message type of the
packages the process then uses is the one a fresh interpreter builds (Quaternion().w == 1.0, the
.msg default), and every message class still has its generated ``__init__``.

Both sides run in interpreters of their own, so that nothing the test session imported before
counts: one walks the project and then dumps the default instances, the other imports only the
message modules and dumps them."""
import json
import subprocess
import sys

# the packages the graph's messages come from; the walk adds whatever else ends up imported
REQUIRED = ["builtin_interfaces", "std_msgs", "geometry_msgs", "sensor_msgs", "diagnostic_msgs", "rosgraph_msgs",
            "visualization_msgs", "cdpr_msgs"]

DUMP = r'''
import array, importlib, json, pkgutil, sys

import numpy as np


def shape(value):
    """The type of a field value, recursively (array.array and numpy arrays with their element type)."""
    if hasattr(type(value), "SLOT_TYPES"):
        return {name: shape(getattr(value, name)) for name in type(value).get_fields_and_field_types()}
    if isinstance(value, array.array):
        return "array.array:" + value.typecode
    if isinstance(value, np.ndarray):
        return "ndarray:" + str(value.dtype)
    if isinstance(value, list):
        return [shape(v) for v in value]
    return type(value).__name__


def classes(package):
    """The message classes of ``package``: its msg module's and its services' requests and responses."""
    for kind in ("msg", "srv"):
        try:
            module = importlib.import_module(f"{package}.{kind}")
        except ImportError:
            continue
        for name, cls in sorted(vars(module).items()):
            if kind == "srv" and hasattr(cls, "Request"):
                yield f"{package}/srv/{name}_Request", cls.Request
                yield f"{package}/srv/{name}_Response", cls.Response
            elif isinstance(cls, type) and hasattr(cls, "SLOT_TYPES"):
                yield f"{package}/{kind}/{name}", cls


def dump(packages):
    out = {}
    for package in packages:
        for key, cls in classes(package):
            init = cls.__dict__.get("__init__")
            msg = cls()
            out[key] = {"repr": repr(msg), "shape": shape(msg),
                        "init": None if init is None else [init.__code__.co_filename, init.__qualname__],
                        "generated_init": [sys.modules[cls.__module__].__file__, cls.__qualname__ + ".__init__"]}
    return out


if sys.argv[1] == "project":
    failed = []
    for top in ("cdpr_control", "cdpr_sim", "cdpr_tools"):
        package = importlib.import_module(top)
        for info in pkgutil.walk_packages(package.__path__, top + ".", onerror=failed.append):
            try:
                importlib.import_module(info.name)
            except Exception as exc:          # reported by the test, with the module's name
                failed.append(f"{info.name}: {exc!r}")
    used = {name.split(".")[0] for name in sys.modules if name.endswith((".msg", ".srv"))}
    packages = sorted(used | set(sys.argv[2:]))
    print(json.dumps({"failed": failed, "packages": packages, "modules": len(sys.modules),
                      "defaults": dump(packages)}))
else:
    print(json.dumps({"defaults": dump(sys.argv[2:])}))
'''


def run(*args: str) -> dict:
    done = subprocess.run([sys.executable, "-c", DUMP, *args], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_importing_the_project_changes_no_message_class():
    project = run("project", *REQUIRED)
    assert project["failed"] == []
    assert set(REQUIRED) <= set(project["packages"]) and "rcl_interfaces" in project["packages"]
    fresh = run("fresh", *project["packages"])
    defaults = project["defaults"]
    assert len(defaults) > 120 and defaults.keys() == fresh["defaults"].keys()
    changed = sorted(key for key in defaults if defaults[key] != fresh["defaults"][key])
    assert changed == []
    for key, entry in defaults.items():      # the __init__ of the class's own generated module
        assert entry["init"] == entry["generated_init"], key
    # the .msg defaults the patching of the past lost
    assert defaults["geometry_msgs/msg/Quaternion"]["repr"] == "geometry_msgs.msg.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)"
    assert "orientation=geometry_msgs.msg.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)" in \
        defaults["visualization_msgs/msg/Marker"]["repr"]
    assert "status=-2" in defaults["sensor_msgs/msg/NavSatStatus"]["repr"]

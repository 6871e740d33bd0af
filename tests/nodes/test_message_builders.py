"""message_builders: for every message class of the packages the project uses, builder(cls)() is the
generated constructor's default instance and builder(cls)(**fields) its instance for random fields
(equal, same field types, same aliasing of what was given, same bytes), without changing the class."""
import array
import importlib
import os
import random
import subprocess
import sys

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosidl_parser.definition import (AbstractGenericString, AbstractNestedType, Array, BasicType, BoundedSequence,
                                      NamespacedType)

from cdpr_control.ros.message_builders import builder
from cdpr_tools.bag.encode import encoder
from cdpr_tools.message_convert import type_name_of

PACKAGES = ["builtin_interfaces", "std_msgs", "geometry_msgs", "sensor_msgs", "diagnostic_msgs", "rosgraph_msgs",
            "visualization_msgs", "cdpr_msgs", "rcl_interfaces", "trajectory_msgs", "nav_msgs"]
# what the nodes build every period: these get a compiled builder, not the generated constructor
GRAPH_BUILT = ["cdpr_msgs/msg/CableForces", "cdpr_msgs/msg/ControllerState", "cdpr_msgs/msg/ForceDistribution",
               "cdpr_msgs/msg/ForwardKinematicsDiagnostics", "cdpr_msgs/msg/OperationalSetpoint",
               "cdpr_msgs/msg/ProgramStatus", "sensor_msgs/msg/JointState", "geometry_msgs/msg/PoseStamped",
               "geometry_msgs/msg/TwistStamped", "geometry_msgs/msg/WrenchStamped", "geometry_msgs/msg/InertiaStamped",
               "rosgraph_msgs/msg/Clock", "visualization_msgs/msg/MarkerArray", "std_msgs/msg/Header"]
_INT_BITS = {"int8": 8, "int16": 16, "int32": 32, "int64": 64}
_UINT_BITS = {"octet": 8, "uint8": 8, "uint16": 16, "uint32": 32, "uint64": 64}
_ARRAY_CODES = {"float": "f", "double": "d", "int8": "b", "uint8": "B", "int16": "h", "uint16": "H", "int32": "i",
                "uint32": "I", "int64": "q", "uint64": "Q"}
TEXT = "abz_/é€"



@pytest.fixture(autouse=True)
def compiled_builders(monkeypatch):
    """The compiled builders under test: the suite runs with ROS_PYTHON_CHECK_FIELDS=1 (where
    builder(cls) is the generated constructor), so it is 0 here, and no builder made here is kept
    for the other tests."""
    from cdpr_control.ros import message_builders

    monkeypatch.setenv("ROS_PYTHON_CHECK_FIELDS", "0")
    kept = dict(message_builders._builders)
    message_builders._builders.clear()
    yield
    message_builders._builders.clear()
    message_builders._builders.update(kept)

def all_classes() -> dict:
    found = {}
    for package in PACKAGES:
        module = importlib.import_module(f"{package}.msg")
        found.update({type_name_of(c): c for c in vars(module).values() if isinstance(c, type) and hasattr(c, "SLOT_TYPES")})
    return found


CLASSES = all_classes()


def scalar(typename: str, rng: random.Random):
    if typename == "boolean":
        return rng.random() < 0.5
    if typename == "double":
        return rng.choice([0.0, -0.0, 1.5, rng.uniform(-1e3, 1e3)])
    if typename == "float":
        return float(np.float32(rng.uniform(-1e3, 1e3)))
    if typename == "octet":
        return bytes([rng.randint(0, 255)])
    if typename == "char":
        return rng.randint(0, 127)
    if typename in _INT_BITS:
        bound = 2 ** (_INT_BITS[typename] - 1)
        return rng.randint(-bound, bound - 1)
    return rng.randint(0, 2 ** _UINT_BITS[typename] - 1)


def value(slot_type, rng: random.Random):
    """A random value for a field, in one of the forms the generated setter takes."""
    if isinstance(slot_type, BasicType):
        return scalar(slot_type.typename, rng)
    if isinstance(slot_type, AbstractGenericString):
        size = slot_type.maximum_size if slot_type.has_maximum_size() else 9
        return "".join(rng.choice(TEXT) for _ in range(rng.randint(0, min(size, 9))))
    if isinstance(slot_type, NamespacedType):
        return random_message(CLASSES["/".join(slot_type.namespaced_name())], rng)
    if not isinstance(slot_type, AbstractNestedType):
        raise NotImplementedError(repr(slot_type))
    n = slot_type.size if isinstance(slot_type, Array) else rng.choice([0, 1, 3])
    if isinstance(slot_type, BoundedSequence):
        n = min(n, slot_type.maximum_size)
    items = [value(slot_type.value_type, rng) for _ in range(n)]
    code = _ARRAY_CODES.get(getattr(slot_type.value_type, "typename", None))
    if code is None:
        return items
    form = rng.choice(["list", "tuple", "numpy", "array"])     # numbers: each form the setter converts
    if form == "tuple":
        return tuple(items)
    if form == "numpy":
        return np.array(items, dtype=np.dtype(code))
    return array.array(code, items) if form == "array" else items


def random_fields(cls, rng: random.Random) -> dict:
    """Random values for a random subset of the fields of ``cls`` (the others keep their defaults)."""
    fields = zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES)
    return {name: value(t, rng) for name, t in fields if rng.random() < 0.7}


def random_message(cls, rng: random.Random):
    return cls(**random_fields(cls, rng))


def shape(value):
    """The type of a field value, recursively (array.array and numpy arrays with their element type)."""
    if hasattr(type(value), "SLOT_TYPES"):
        return {name: shape(getattr(value, name)) for name in type(value).get_fields_and_field_types()}
    if isinstance(value, array.array):
        return "array.array:" + value.typecode
    if isinstance(value, np.ndarray):
        return f"ndarray:{value.dtype}:{value.shape}"
    if isinstance(value, list):
        return [shape(v) for v in value]
    return type(value).__name__


def same_message(built, generated) -> None:
    """Equal, with the same field types, and the same bytes on the wire."""
    assert type(built) is type(generated) and built == generated
    assert shape(built) == shape(generated)
    assert built._check_fields is False
    data, theirs = serialize_message(built), serialize_message(generated)
    assert deserialize_message(data, type(generated)) == generated
    encode = encoder(type_name_of(generated))
    if encode is None:              # no encoder of the project's for this type: the bytes' length
        assert len(data) == len(theirs)
        return
    assert bytes(encode(built)) == bytes(encode(generated))
    # FastCDR leaves stale bytes in alignment padding (tests/tools/test_bag_encode.py): rclpy's bytes agree
    # wherever the encoding, which zeroes the padding, has a byte that is not a pad
    padded = bytes(encode(generated))
    assert len(data) == len(theirs) and all(a == b for a, b, p in zip(data, theirs, padded) if p != 0)


@pytest.mark.parametrize("type_name", sorted(CLASSES))
def test_default_is_the_generated_default(type_name):
    cls = CLASSES[type_name]
    build = builder(cls)
    same_message(build(), cls())
    first, second = build(), build()                # no mutable default shared between instances
    for name in cls.get_fields_and_field_types():
        a = getattr(first, name)
        assert isinstance(a, (bool, int, float, str, bytes)) or a is not getattr(second, name), name


@pytest.mark.parametrize("type_name", sorted(CLASSES))
def test_given_fields_are_stored_as_the_generated_constructor_stores_them(type_name):
    cls = CLASSES[type_name]
    rng = random.Random(type_name)
    for _ in range(10):
        fields = random_fields(cls, rng)
        built, generated = builder(cls)(**fields), cls(check_fields=False, **fields)   # (the suite checks fields)
        same_message(built, generated)
        for name, given in fields.items():          # what is kept, and what is copied, as generated
            assert (getattr(built, name) is given) == (getattr(generated, name) is given), name


def test_graph_types_get_a_compiled_builder():
    for type_name in GRAPH_BUILT:
        cls = CLASSES[type_name]
        assert builder(cls) is not cls and builder(cls) is builder(cls), type_name


def test_msg_defaults_are_kept():
    from geometry_msgs.msg import Pose, Quaternion
    from sensor_msgs.msg import NavSatFix, NavSatStatus
    from visualization_msgs.msg import Marker
    assert builder(Quaternion)().w == 1.0 and builder(Pose)().orientation.w == 1.0
    assert builder(Marker)().pose.orientation.w == 1.0
    assert builder(NavSatStatus)().status == -2 and builder(NavSatFix)().status.status == -2
    assert builder(Quaternion)(x=0.5).w == 1.0 and builder(Quaternion)(w=0.0).w == 0.0


def test_no_class_is_changed():
    for cls in CLASSES.values():
        builder(cls)
        init = cls.__dict__["__init__"]
        assert init.__code__.co_filename == sys.modules[cls.__module__].__file__
        assert init.__qualname__ == f"{cls.__name__}.__init__"


def test_unknown_field_is_an_error_naming_it():
    from cdpr_msgs.msg import OperationalSetpoint
    with pytest.raises(TypeError, match="posee"):
        builder(OperationalSetpoint)(posee=None)


def test_field_checks_asked_for_give_the_generated_constructor():
    code = ("from cdpr_control.ros.message_builders import builder\n"
            "from cdpr_msgs.msg import OperationalSetpoint\n"
            "from geometry_msgs.msg import Quaternion\n"
            "assert builder(Quaternion) is Quaternion and builder(OperationalSetpoint) is OperationalSetpoint\n"
            "msg = builder(OperationalSetpoint)()\n"
            "assert msg._check_fields is True and msg.pose.orientation.w == 1.0\n"
            "try:\n"
            "    builder(Quaternion)(w='1')\n"
            "except AssertionError:\n"
            "    print('checked')\n")
    env = {**os.environ, "ROS_PYTHON_CHECK_FIELDS": "1"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["checked"]

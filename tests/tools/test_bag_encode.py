"""The bag's own CDR encoder (cdpr_tools.bag.encode) writes rclpy's bytes for every message type of
the graph: the same length, header and field bytes as FastDDS's (cut to the encoding), and zeros
where FastCDR leaves stale bytes as alignment padding."""
import importlib
import random

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosidl_parser.definition import (AbstractSequence, AbstractString, Array, BasicType, NamespacedType)

from cdpr_control.ros.message_builders import builder
from cdpr_tools.bag.cdr import trimmed
from cdpr_control.ros.cdr import HEADER
from cdpr_tools.bag.encode import encoder, serialize
from cdpr_tools.message_convert import message_class, type_name_of

# what closed_loop.yaml publishes (and the recorder records) but /parameter_events, whose octet sequences
# rclpy serializes (it is checked with every type of the packages below)
GRAPH_TYPES = [
    "cdpr_msgs/msg/CableForces", "cdpr_msgs/msg/ControllerState", "cdpr_msgs/msg/ForceDistribution",
    "cdpr_msgs/msg/ForwardKinematicsDiagnostics", "cdpr_msgs/msg/OperationalSetpoint", "cdpr_msgs/msg/ProgramStatus",
    "sensor_msgs/msg/JointState", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/TwistStamped",
    "geometry_msgs/msg/WrenchStamped", "geometry_msgs/msg/InertiaStamped", "rosgraph_msgs/msg/Clock",
    "std_msgs/msg/String", "diagnostic_msgs/msg/DiagnosticArray", "rcl_interfaces/msg/Log",
    "visualization_msgs/msg/MarkerArray"]
PACKAGES = ["builtin_interfaces", "std_msgs", "geometry_msgs", "sensor_msgs", "diagnostic_msgs", "rosgraph_msgs",
            "visualization_msgs", "cdpr_msgs", "rcl_interfaces", "trajectory_msgs", "nav_msgs"]
_RANGES = {"int8": (-128, 127), "uint8": (0, 255), "int16": (-2**15, 2**15 - 1), "uint16": (0, 2**16 - 1),
           "int32": (-2**31, 2**31 - 1), "uint32": (0, 2**32 - 1), "int64": (-2**63, 2**63 - 1),
           "uint64": (0, 2**64 - 1)}
_NUMPY = {"float": np.float32, "double": np.float64, "boolean": np.bool_, **{t: getattr(np, t) for t in _RANGES}}
TEXT = "abcxyz_/é€"   # one-, two- and three-byte UTF-8: every string length modulo 4


def all_types():
    names = set(GRAPH_TYPES)
    for package in PACKAGES:
        try:
            module = importlib.import_module(f"{package}.msg")
        except ImportError:
            continue
        names.update(type_name_of(c) for c in vars(module).values() if isinstance(c, type) and hasattr(c, "SLOT_TYPES"))
    return sorted(names)


def value(slot_type, rng: random.Random):
    if isinstance(slot_type, BasicType):
        t = slot_type.typename
        if t == "boolean":
            return rng.random() < 0.5
        if t in ("float", "double"):
            return rng.choice([0.0, -0.0, 1.5, rng.uniform(-1e3, 1e3), rng.uniform(-1e-3, 1e-3)])
        if t == "octet":
            return bytes([rng.randint(0, 255)])
        if t == "char":
            return rng.randint(0, 255)
        if t in _RANGES:
            lo, hi = _RANGES[t]
            return rng.choice([lo, hi, 0, rng.randint(lo, hi)])
        raise NotImplementedError(t)
    if isinstance(slot_type, AbstractString):
        return "".join(rng.choice(TEXT) for _ in range(rng.randint(0, 9)))
    if isinstance(slot_type, NamespacedType):
        return fill(message_class("/".join(slot_type.namespaced_name())), rng)
    if isinstance(slot_type, Array):
        items = [value(slot_type.value_type, rng) for _ in range(slot_type.size)]
        if isinstance(slot_type.value_type, BasicType):
            return np.array(items, dtype=_NUMPY[slot_type.value_type.typename])
        return items
    if isinstance(slot_type, AbstractSequence):
        return [value(slot_type.value_type, rng) for _ in range(rng.choice([0, 0, 1, 2, 3, 5]))]
    raise NotImplementedError(repr(slot_type))


def fill(cls, rng: random.Random):
    """A message as the graph builds it (message_builders), random values in every field set through
    the generated setters."""
    msg = builder(cls)()
    for name, slot_type in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES):
        setattr(msg, name, value(slot_type, rng))
    return msg


def check_same_encoding(msg, ours: bytes, zero_padding: bool = True) -> None:
    theirs = trimmed(type_name_of(msg), serialize_message(msg))
    assert len(ours) == len(theirs) and ours[:4] == theirs[:4] == HEADER
    # rclpy reads our bytes back to what it reads from its own
    assert deserialize_message(ours, type(msg)) == deserialize_message(theirs, type(msg))
    # and every byte but padding is the same: where they differ, ours is a zero pad and theirs stale
    assert not zero_padding or all(a == 0 for a, b in zip(ours, theirs) if a != b)


@pytest.mark.parametrize("type_name", GRAPH_TYPES)
def test_the_graph_types_have_an_encoder(type_name):
    assert encoder(type_name) is not None


@pytest.mark.parametrize("type_name", all_types())
def test_encoding_is_rclpys_for_random_messages(type_name):
    cls, encode = message_class(type_name), encoder(type_name)
    if encode is None:          # no encoder for this type (wide strings, bounded fields): rclpy's bytes, cut
        check_same_encoding(cls(), serialize(cls()), zero_padding=False)
        return
    rng = random.Random(type_name)
    check_same_encoding(cls(), encode(cls()))
    check_same_encoding(builder(cls)(), encode(builder(cls)()))
    for _ in range(40):
        msg = fill(cls, rng)
        check_same_encoding(msg, encode(msg))


def test_values_as_rclpy_takes_them():
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    joints = JointState(name=["a", "bb"], position=[1.0, 2.0])
    joints._velocity = np.array([3.0, 4.0])                 # a buffer in a slot: its bytes
    joints._effort = [5.0, 6.5]                             # a list: element by element
    check_same_encoding(joints, serialize(joints))
    for name in ("c", "dd", "c"):                           # names found by content: a changed list anew
        joints.name[1] = name
        check_same_encoding(joints, serialize(joints))
    check_same_encoding(String(data="cut\0here"), serialize(String(data="cut\0here")))  # C string: up to NUL

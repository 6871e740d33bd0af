"""Faster constructors for the generated message classes the graph builds every control period.

The rosidl-generated ``__init__`` of a message imports its field types inside the call, builds a
default for every field before looking at the caller's value (``OperationalSetpoint(header=h, ...)``
builds and drops a Header with its Time, a Pose with Point and Quaternion, a Twist, an Accel, a
Wrench) and stores each value through the field's property. Every node builds several messages a
period, so :func:`install` gives the message classes of the packages the graph uses an
``__init__`` generated like the dataclasses' one: the given values go straight into the slots,
converted as the generated constructor converts them (numeric sequences to ``array.array``, a
copy), and a default is built only for a field not given. The messages are the same (equal,
same bytes: tests/nodes/test_node_messages.py); an OperationalSetpoint built from header and pose takes 1.8 us
instead of 10.7.

Classes with fields this does not cover (fixed-size arrays, which the generated code keeps as
numpy arrays; characters, octets, wide strings) keep their constructor, and so does every class
when ``ROS_PYTHON_CHECK_FIELDS=1`` asks for the generated field checks.
"""
from __future__ import annotations

import array
import importlib
import os

from rosidl_parser.definition import (AbstractSequence, AbstractString, AbstractWString, BasicType,
    NamespacedType)

PACKAGES = ("builtin_interfaces", "std_msgs", "geometry_msgs", "sensor_msgs", "diagnostic_msgs",
            "rosgraph_msgs", "visualization_msgs", "cdpr_msgs")
_ARRAY_CODES = {"float": "f", "double": "d", "int8": "b", "uint8": "B", "int16": "h", "uint16": "H",
                "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q"}
_SCALAR_DEFAULTS = {**{t: "0" for t in _ARRAY_CODES}, "float": "0.0", "double": "0.0", "boolean": "False"}


def _field_code(name: str, slot_type, env: dict) -> str | None:
    """The statement setting field ``name`` from ``kwargs``; None where this module does not cover the type."""
    if isinstance(slot_type, NamespacedType):
        cls_name = f"_{'_'.join(slot_type.namespaces)}_{slot_type.name}"
        env[cls_name] = getattr(importlib.import_module(".".join(slot_type.namespaces)), slot_type.name)
        return f"self._{name} = kwargs['{name}'] if '{name}' in kwargs else {cls_name}()"
    if isinstance(slot_type, AbstractWString):
        return None
    if isinstance(slot_type, AbstractString):
        return f"self._{name} = kwargs.get('{name}', '')"
    if isinstance(slot_type, BasicType):
        default = _SCALAR_DEFAULTS.get(slot_type.typename)
        return None if default is None else f"self._{name} = kwargs.get('{name}', {default})"
    if isinstance(slot_type, AbstractSequence):
        value = slot_type.value_type
        if isinstance(value, BasicType):
            code = _ARRAY_CODES.get(value.typename)
            if code is not None:
                return f"self._{name} = _array('{code}', kwargs.get('{name}', ()))"
            if value.typename != "boolean":
                return None
        elif isinstance(value, AbstractWString):
            return None
        elif isinstance(value, NamespacedType):
            _field_code("_", value, env)     # import it now, as the generated constructor would
        return f"self._{name} = kwargs.get('{name}', [])"
    return None                               # fixed-size arrays and anything else


def fast_init(cls):
    """A generated ``__init__(self, **kwargs)`` for message class ``cls``, or None if not covered."""
    names = [s[1:] for s in cls.__slots__ if s != "_check_fields"]
    env: dict = {"_array": array.array}
    lines = ["def __init__(self, **kwargs):",
             "    if 'check_fields' in kwargs and kwargs['check_fields']:",
             "        return _generated(self, **kwargs)",
             "    self._check_fields = False"]
    for name, slot_type in zip(names, cls.SLOT_TYPES):
        code = _field_code(name, slot_type, env)
        if code is None:
            return None
        lines.append("    " + code)
    env["_generated"] = cls.__init__
    exec("\n".join(lines), env)                 # noqa: S102 - code built from the message definition only
    init = env["__init__"]
    init.__qualname__ = f"{cls.__name__}.__init__"
    init.__doc__ = "Fast constructor (cdpr_control.ros.message_init); same fields and values as the generated one."
    return init


def install(packages=PACKAGES) -> list[type]:
    """Give the message classes of ``packages`` the fast constructor (once); the classes changed."""
    if os.environ.get("ROS_PYTHON_CHECK_FIELDS", "") == "1":
        return []
    changed = []
    for package in packages:
        try:
            module = importlib.import_module(f"{package}.msg")
        except ImportError:
            continue
        for cls in vars(module).values():
            if not (isinstance(cls, type) and hasattr(cls, "SLOT_TYPES") and hasattr(cls, "__slots__")):
                continue
            if getattr(cls.__init__, "__doc__", "") and "message_init" in cls.__init__.__doc__:
                continue                          # already installed
            init = fast_init(cls)
            if init is not None:
                cls.__init__ = init
                changed.append(cls)
    return changed


install()

"""Fast constructors of message instances for the project's own nodes, without touching the classes.

The rosidl-generated ``__init__`` of a message imports its field types inside the call, builds a
default for every field before looking at the caller's value (``OperationalSetpoint(header=h, ...)``
builds and drops a Header with its Time, a Pose with Point and Quaternion, a Twist, an Accel and a
Wrench) and stores each value through the field's property. The nodes build several messages a
period, so they call ``builder(cls)(**fields)`` instead: a function compiled once per class from
the message definition that makes an ordinary instance of the real class (``cls.__new__`` and its
slots) and builds a default only for a field not given. Nothing is patched: ``cls()`` stays the
generated constructor for everyone else in the process.

What a builder stores is what the generated constructor stores (with ``check_fields`` off):

* a field not given gets the ``.msg`` default, read from one instance built by the generated
  constructor (``Quaternion.w`` is 1.0, ``NavSatStatus.status`` -2); a nested message its own
  builder's default; a sequence or array a fresh copy of the default (never a shared object);
* a given value is stored as the generated property setter stores it: numeric sequences copied
  into ``array.array``, numeric fixed-size arrays into a numpy array of the field's dtype,
  everything else as given (a list or a nested message is not copied).

Departures, on purpose: an unknown field name is a ``TypeError`` (the generated constructor ignores
it unless field checks are on), and no ``check_fields`` argument is taken. With
``ROS_PYTHON_CHECK_FIELDS=1`` in the environment when a builder is made, the builder *is* the
generated constructor, with its field checks. A class with a field this module does not cover
(a Python keyword as field name, a default list of messages) also gets its generated constructor.
tests/nodes/test_message_builders.py checks every class of the packages the project uses.
"""
from __future__ import annotations

import array
import keyword
import os

import numpy as np
from rosidl_parser.definition import AbstractGenericString, AbstractNestedType, BasicType, NamespacedType

_IMMUTABLE = (bool, int, float, str, bytes)
_MISSING = object()       # the value of a builder's keyword argument not given
_builders: dict[type, object] = {}


def builder(cls):
    """The constructor function of message class ``cls``: ``builder(cls)(**fields)`` equals ``cls(**fields)``.

    Compiled on the first call per class; the generated constructor ``cls`` itself where field
    checks are asked for or the class is not covered (see the module docstring)."""
    made = _builders.get(cls)
    if made is None:
        made = cls if os.environ.get("ROS_PYTHON_CHECK_FIELDS", "") == "1" else _compile(cls)
        _builders[cls] = made
    return made


def _field_code(name: str, slot_type, default, env: dict) -> str | None:
    """The statement storing field ``name`` (a keyword argument of the builder, ``_MISSING`` if not
    given) into the instance ``_msg``; None where this module does not cover the field. Every other
    name in the code starts with an underscore, which no field name does (rosidl), so no field
    shadows it (rcl_interfaces/Log has a field ``msg``, others ``id``, ``type``)."""
    d = f"_d_{name}"
    if isinstance(slot_type, NamespacedType):
        if not hasattr(type(default), "SLOT_TYPES"):
            return None
        env[f"_b_{name}"] = builder(type(default))   # the nested class, as the generated constructor imports it
        return f"_msg._{name} = _b_{name}() if {name} is _MISSING else {name}"
    if isinstance(slot_type, (BasicType, AbstractGenericString)):
        if not isinstance(default, _IMMUTABLE):
            return None
        env[d] = default
        return f"_msg._{name} = {d} if {name} is _MISSING else {name}"
    if not isinstance(slot_type, AbstractNestedType):
        return None
    if isinstance(default, array.array):           # numeric sequence: the setter's array.array(code, value)
        env[d], env[f"_c_{name}"] = array.array(default.typecode, default), default.typecode
        return f"_msg._{name} = _array(_c_{name}, {d} if {name} is _MISSING else {name})"
    if isinstance(default, np.ndarray):            # numeric fixed-size array: the setter's numpy.array(value, dtype)
        env[d], env[f"_t_{name}"] = default.copy(), default.dtype
        return f"_msg._{name} = _ndarray({d} if {name} is _MISSING else {name}, dtype=_t_{name})"
    if isinstance(default, list) and all(isinstance(v, _IMMUTABLE) for v in default):
        env[d] = tuple(default)                    # the setter stores a given list itself; a default is a new list
        return f"_msg._{name} = _list({d}) if {name} is _MISSING else {name}"
    return None


def _compile(cls):
    """The builder function of ``cls`` compiled from its definition, or ``cls`` where not covered."""
    names = list(cls.get_fields_and_field_types())
    if any(keyword.iskeyword(n) for n in names):
        return cls
    default = cls(check_fields=False)
    env: dict = {"_MISSING": _MISSING, "_new": cls.__new__, "_cls": cls, "_array": array.array,
                 "_ndarray": np.array, "_list": list}
    body = []
    for name, slot_type in zip(names, cls.SLOT_TYPES):
        code = _field_code(name, slot_type, getattr(default, name), env)
        if code is None:
            return cls
        body.append("    " + code)
    params = f"*, {', '.join(f'{n}=_MISSING' for n in names)}" if names else ""
    source = "\n".join([f"def build({params}):", "    _msg = _new(_cls)", "    _msg._check_fields = False",
                        *body, "    return _msg"])
    exec(source, env)                              # noqa: S102 - source built from the message definition only
    build = env["build"]
    build.__name__ = build.__qualname__ = f"build_{cls.__name__}"
    build.__doc__ = (f"A {cls.__module__.split('.')[0]}/{cls.__name__} with the given fields and the .msg defaults "
                     "for the others (cdpr_control.ros.message_builders).")
    return build

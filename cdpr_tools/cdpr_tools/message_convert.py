"""ROS messages to and from plain Python (dicts, lists, YAML), by rosidl introspection.

There is no rosidl_runtime_py wheel, so this module is the project's one place for
``"pkg/msg/Type"`` -> class lookup and for the conversions ``cdpr topic echo/pub`` and the bag
tools need. Field types come from the generated classes themselves (``SLOT_TYPES``,
``get_fields_and_field_types``), so every installed interface works without a parser.
"""
from __future__ import annotations

import functools
import importlib
import re
from typing import Any, Callable

import yaml
from rosidl_parser.definition import (
    AbstractNestedType,
    Array,
    BasicType,
    NamespacedType,
)

# "pkg/msg/Type", "pkg/Type" (msg implied) or "pkg.msg.Type"
_TYPE_NAME = re.compile(r"^(?P<pkg>[A-Za-z]\w*)[/.](?:(?P<kind>msg|srv|action)[/.])?(?P<name>[A-Za-z]\w*)$")
_FLOAT_TYPES = {"float", "double", "long double"}
_INT_TYPES = {"char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64"}


def split_type_name(type_name: str) -> tuple[str, str, str]:
    """``"pkg/msg/Type"`` (or ``"pkg/Type"``, ``"pkg.msg.Type"``) -> ``("pkg", "msg", "Type")``."""
    match = _TYPE_NAME.match(type_name.strip())
    if not match:
        raise ValueError(f"not an interface type name: {type_name!r} (expected pkg/msg/Type)")
    return match["pkg"], match["kind"] or "msg", match["name"]


@functools.lru_cache(maxsize=None)
def message_class(type_name: str) -> type:
    """The generated Python class of an installed interface, e.g. ``message_class("std_msgs/msg/String")``.

    Accepts msg, srv and action types; raises ``LookupError`` naming what is installed instead.
    """
    pkg, kind, name = split_type_name(type_name)
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
    except ModuleNotFoundError:
        raise LookupError(f"unknown type {type_name}: no interface package {pkg!r} is installed") from None
    cls = getattr(module, name, None)
    if cls is None or not isinstance(cls, type):
        known = sorted(n for n, v in vars(module).items() if isinstance(v, type) and not n.startswith("_"))
        raise LookupError(f"unknown type {type_name}: {pkg}/{kind} has {', '.join(known)}")
    return cls


def type_name_of(msg_or_class: Any) -> str:
    """``"pkg/msg/Type"`` of a message instance or class (also srv/action)."""
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    pkg, kind = cls.__module__.split(".")[:2]
    return f"{pkg}/{kind}/{cls.__name__}"


def is_message(value: Any) -> bool:
    return hasattr(type(value), "SLOT_TYPES") and hasattr(type(value), "get_fields_and_field_types")


def _fields(cls: type) -> list[tuple[str, Any]]:
    """(field name, rosidl type) pairs of a message class, in declaration order."""
    return list(zip(cls.get_fields_and_field_types().keys(), cls.SLOT_TYPES))


def message_to_dict(msg: Any) -> dict:
    """Nested dict of plain Python values (lists for arrays, int for bytes) in field order."""
    return {name: _to_python(getattr(msg, name)) for name, _ in _fields(type(msg))}


def _to_python(value: Any) -> Any:
    if is_message(value):
        return message_to_dict(value)
    if isinstance(value, bytes) and len(value) == 1:  # rclpy gives byte/octet fields as 1-byte bytes
        return value[0]
    if hasattr(value, "tolist"):  # numpy arrays (fixed-size) and array.array (sequences)
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_to_python(v) for v in value]
    return value


def message_to_yaml(msg: Any) -> str:
    """YAML of a message as ``ros2 topic echo`` prints it (block style, field order kept)."""
    return yaml.safe_dump(message_to_dict(msg), sort_keys=False, default_flow_style=False,
                          allow_unicode=True, width=10_000)


def dict_to_message(msg_type: str | type, values: dict | None = None, now: Callable[[], Any] | None = None) -> Any:
    """A message of ``msg_type`` (name or class) with the fields given in ``values`` set.

    ``now`` returns a ``builtin_interfaces/msg/Time``; when given, the string ``"now"`` is accepted
    for any Time field (as ``ros2 topic pub`` does).
    """
    cls = message_class(msg_type) if isinstance(msg_type, str) else msg_type
    return set_message_fields(cls(), values or {}, now)


def set_message_fields(msg: Any, values: dict, now: Callable[[], Any] | None = None) -> Any:
    """Set the fields of ``msg`` from a (nested) dict; unknown fields raise with the valid names."""
    if not isinstance(values, dict):
        raise TypeError(f"{type_name_of(msg)}: expected a mapping of field values, got {values!r}")
    fields = dict(_fields(type(msg)))
    for name, value in values.items():
        if name not in fields:
            raise ValueError(f"{type_name_of(msg)} has no field {name!r}; fields: {', '.join(fields) or '(none)'}")
        try:
            setattr(msg, name, _from_python(fields[name], value, getattr(msg, name), now))
        except (TypeError, ValueError, AssertionError) as exc:
            raise ValueError(f"{type_name_of(msg)}.{name}: cannot set {value!r}: {exc}") from None
    return msg


def _from_python(slot: Any, value: Any, current: Any, now: Callable[[], Any] | None) -> Any:
    if isinstance(slot, NamespacedType):
        if value == "now" and now is not None and slot.namespaced_name() == ("builtin_interfaces", "msg", "Time"):
            return now()
        return set_message_fields(type(current)(), value, now)
    if isinstance(slot, AbstractNestedType):  # Array, BoundedSequence, UnboundedSequence
        if not isinstance(value, (list, tuple)):
            raise TypeError(f"expected a list, got {type(value).__name__}")
        if isinstance(slot, Array) and len(value) != slot.size:
            raise ValueError(f"expected {slot.size} elements, got {len(value)}")
        element = slot.value_type
        if isinstance(element, NamespacedType):
            cls = message_class("/".join(element.namespaced_name()))
            return [v if isinstance(v, cls) else set_message_fields(cls(), v, now) for v in value]
        return [_scalar(element, v) for v in value]
    return _scalar(slot, value)


def _scalar(slot: Any, value: Any) -> Any:
    if not isinstance(slot, BasicType):  # strings
        return str(value)
    if slot.typename in _FLOAT_TYPES:
        return float(value)
    if slot.typename in _INT_TYPES:
        return int(value)
    if slot.typename == "boolean":
        return bool(value)
    if slot.typename == "octet":
        return value if isinstance(value, bytes) else bytes([int(value)])
    return value


def field_value(msg: Any, path: str) -> Any:
    """Value at a dotted field path, e.g. ``field_value(msg, "header.stamp.sec")``."""
    value = msg
    for part in path.split("."):
        if not hasattr(value, "get_fields_and_field_types") or part not in value.get_fields_and_field_types():
            fields = ", ".join(value.get_fields_and_field_types()) if is_message(value) else "(not a message)"
            raise ValueError(f"no field {part!r} in {path!r}; fields there: {fields}")
        value = getattr(value, part)
    return value

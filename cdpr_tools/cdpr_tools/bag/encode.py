"""The CDR bytes of a message as a bag stores them: cdpr_control.ros.cdr's generated encoders by type
name, rclpy's serializer (cut to the encoding) for what they do not cover."""
from __future__ import annotations

from typing import Callable

from rclpy.serialization import serialize_message

from cdpr_control.ros import cdr
from cdpr_tools.bag.cdr import trimmed
from cdpr_tools.message_convert import message_class, type_name_of


def encoder(type_name: str) -> Callable[[object], bytes] | None:
    """``f(msg) -> bytes``: the CDR encoding of a ``pkg/msg/Type`` message (header included, no
    trailing padding), or None for a type with fields it does not cover (cdpr_control.ros.cdr)."""
    return cdr.encoder(message_class(type_name))


def serialize(msg, type_name: str | None = None) -> bytes:
    """The CDR bytes of ``msg`` as a bag stores them: :func:`encoder`'s where the type has one
    (falling back to rclpy for a value it cannot pack), else rclpy's cut to the encoding."""
    type_name = type_name or type_name_of(msg)
    data = cdr.to_bytes(msg, message_class(type_name))
    return trimmed(type_name, serialize_message(msg)) if data is None else data   # rclpy: e.g. a float32 beyond its range

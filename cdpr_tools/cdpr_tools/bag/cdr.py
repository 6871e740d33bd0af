"""Exact length of a CDR-encoded ROS message, to cut the padding some serializers leave behind.

``rclpy.serialization.serialize_message`` (FastDDS typesupport) can return a buffer longer than
the encoding, with stale bytes at the end (seen: sensor_msgs/JointState, 76 bytes for a 68-byte
encoding). ``mcap_ros2`` ignores them, ``rosbags`` refuses more than 3 trailing bytes ("CDR
message size mismatch"), so the bag writer stores only the encoded bytes.

The length is found by walking the buffer with the message layout from rosidl introspection
(``SLOT_TYPES``): XCDR1 as ROS 2 uses it, a 4-byte encapsulation header, then the fields in order,
each primitive aligned to its size (at most 8) relative to the end of the header, strings and
sequences prefixed with a uint32 count. Runs of fixed-size fields collapse into one table per start
alignment, so a message costs one step per string or sequence.
"""
from __future__ import annotations

import functools
import struct
from typing import Callable

from rosidl_parser.definition import (
    AbstractGenericString,
    AbstractSequence,
    AbstractWString,
    Array,
    BasicType,
    NamespacedType,
)

from cdpr_tools.message_convert import message_class

HEADER = 4  # encapsulation kind + options
_U32 = struct.Struct("<I").unpack_from
_BIG_U32 = struct.Struct(">I").unpack_from
_SIZES = {"boolean": 1, "octet": 1, "char": 1, "int8": 1, "uint8": 1, "int16": 2, "uint16": 2,
          "wchar": 4, "int32": 4, "uint32": 4, "float": 4, "int64": 8, "uint64": 8, "double": 8,
          "long double": 8}

# A step maps (buffer, position after the header, uint32 reader) to the position after its field.
Step = Callable[[bytes, int, Callable], int]


class _Fixed:
    """A run of fixed-size fields: bytes it spans for each start position modulo 8."""

    __slots__ = ("advance",)

    def __init__(self, advance: tuple[int, ...]):
        self.advance = advance

    @classmethod
    def primitive(cls, size: int, count: int = 1) -> "_Fixed":
        if count == 0:
            return cls((0,) * 8)
        return cls(tuple((-r) % size + size * count for r in range(8)))

    def then(self, other: "_Fixed") -> "_Fixed":
        return _Fixed(tuple(a + other.advance[(r + a) % 8] for r, a in enumerate(self.advance)))

    def step(self) -> Step:
        advance = self.advance
        return lambda buf, pos, u32: pos + advance[pos % 8]


def _string_step(char_size: int) -> Step:
    def step(buf, pos, u32):
        pos += (-pos) % 4
        return pos + 4 + char_size * u32(buf, HEADER + pos)[0]
    return step


def _strides(advance: tuple[int, ...]) -> tuple[int | None, ...]:
    """Per start residue: the constant advance of every following element, or None if it varies."""
    strides = []
    for r in range(8):
        seen, x, a = set(), r, advance[r]
        while x not in seen and advance[x] == a:
            seen.add(x)
            x = (x + a) % 8
        strides.append(a if x in seen else None)
    return tuple(strides)


def _sequence_step(element: _Fixed | list) -> Step:
    if isinstance(element, _Fixed):
        advance, strides = element.advance, _strides(element.advance)

        def fixed(buf, pos, u32):
            pos += (-pos) % 4
            count = u32(buf, HEADER + pos)[0]
            pos += 4
            while count:  # after the first element (aligned) the rest usually tile with one stride
                pos += advance[pos % 8]
                count -= 1
                stride = strides[pos % 8]
                if stride is not None:
                    return pos + count * stride
            return pos
        return fixed
    steps = element

    def walk(buf, pos, u32):
        pos += (-pos) % 4
        count = u32(buf, HEADER + pos)[0]
        pos += 4
        for _ in range(count):
            for s in steps:
                pos = s(buf, pos, u32)
        return pos
    return walk


def _array_steps(element: _Fixed | list, size: int) -> _Fixed | list:
    if isinstance(element, _Fixed):
        run = _Fixed((0,) * 8)
        for _ in range(size):
            run = run.then(element)
        return run
    return element * size


def _layout(slot) -> _Fixed | list:
    """A fixed run, or a list of steps, for one field type."""
    if isinstance(slot, BasicType):
        return _Fixed.primitive(_SIZES[slot.typename])
    if isinstance(slot, AbstractWString):
        return [_string_step(4)]  # uint32 count, then one 4-byte wchar_t per character
    if isinstance(slot, AbstractGenericString):
        return [_string_step(1)]  # uint32 count including the NUL, then the bytes
    if isinstance(slot, NamespacedType):
        return _message_layout("/".join(slot.namespaced_name()))
    if isinstance(slot, Array):
        return _array_steps(_layout(slot.value_type), slot.size)
    if isinstance(slot, AbstractSequence):
        return [_sequence_step(_layout(slot.value_type))]
    raise TypeError(f"unsupported field type {slot!r}")


@functools.lru_cache(maxsize=None)
def _message_layout(type_name: str) -> _Fixed | list:
    slots = message_class(type_name).SLOT_TYPES
    if not slots:  # rosidl gives empty structures one uint8 member
        return _Fixed.primitive(1)
    steps: list = []
    run: _Fixed | None = None
    for slot in slots:
        part = _layout(slot)
        if isinstance(part, _Fixed):
            run = part if run is None else run.then(part)
            continue
        if run is not None:
            steps.append(run.step())
            run = None
        steps.extend(part)
    if not steps:
        return run
    if run is not None:
        steps.append(run.step())
    return steps


@functools.lru_cache(maxsize=None)
def length_function(type_name: str) -> Callable[[bytes], int]:
    """``f(buffer) -> int``: bytes of the encoded message, header included, for ``pkg/msg/Type``."""
    layout = _message_layout(type_name)
    steps = [layout.step()] if isinstance(layout, _Fixed) else layout

    def length(buf) -> int:
        u32 = _BIG_U32 if buf[1] in (0, 2) else _U32  # CDR_BE = 0x0000, PL_CDR_BE = 0x0002
        pos = 0
        for s in steps:
            pos = s(buf, pos, u32)
        return HEADER + pos
    return length


def trimmed(type_name: str, data: bytes) -> bytes:
    """``data`` without bytes beyond the encoding (unchanged when there are none)."""
    try:
        end = length_function(type_name)(data)
    except (struct.error, IndexError):  # a length prefix beyond the end
        end = len(data) + 1
    if end > len(data):
        raise ValueError(f"{type_name}: {len(data)} bytes of CDR data are not a whole message")
    return data if end == len(data) else data[:end]

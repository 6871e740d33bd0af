"""CDR encoding of ROS messages and payloads in Python, exact and 2 to 15 times faster than ``serialize_message``.

Where a message leaves the process, its bytes are made here: the intra-process publisher
(intraprocess.py) writes a payload (adapted.py) or message to DDS as these bytes
(``publish_raw``) instead of handing rclpy the message to convert, and the bag recorder
(cdpr_tools.bag) stores them. ``rclpy.serialization.serialize_message`` and rclpy's ``publish``
cost 3-11 us a message more: rclpy first copies the whole message into its C struct (one attribute
lookup, type check and allocation per field, nested messages through their own converters), then
FastCDR encodes it. :func:`encoder` instead generates one Python function per type from the rosidl
layout (``SLOT_TYPES``), which reads the fields from their slots and packs each run of fixed-size
fields with one precompiled ``struct`` call, picked by the run's start position modulo 8 where that
is only known at run time (after a string or sequence). Lists of strings (joint and axis names) are
encoded once and looked up by their content afterwards.

The bytes are XCDR1 little endian as ROS 2 uses it (see cdpr_tools.bag.cdr): what FastDDS writes, cut to
the encoding, except that the alignment padding is zero, where FastCDR leaves whatever its buffer
held (so rclpy's own bytes differ from call to call there; no reader looks at them).
tests/tools/test_bag_encode.py checks this on random messages of every type of the graph and of the
interface packages around it. Types with fields this does not cover (wide strings, sequences and
arrays of char or octet, long double, bounded strings and sequences, whose bounds rclpy enforces)
get no encoder (None): the caller then uses rclpy. Values are taken as rclpy takes them (for
the values the generated setters accept): numeric sequences by their buffer (``array.array``,
numpy arrays; inline for ``array.array``, float64 numpy arrays and tuples, what messages and the
payloads of cdpr_control.ros.adapted hold) or element by element, strings as UTF-8 up to the first NUL, booleans true only if
they are ``True``. A value rclpy would refuse or convert (a float32 beyond its range, which rclpy
makes inf) raises one of :data:`ENCODE_ERRORS`: the caller then uses rclpy.
"""
from __future__ import annotations

import functools
import importlib
import struct
from array import array
from typing import Callable

import numpy as np
from rosidl_parser.definition import (
    AbstractGenericString,
    AbstractSequence,
    AbstractString,
    Array,
    BasicType,
    BoundedSequence,
    BoundedString,
    NamespacedType,
)


HEADER = b"\x00\x01\x00\x00"  # CDR_LE encapsulation, options 0 (as FastDDS writes it)
NAMES_CACHE = 64  # encoded lists of strings kept per field (the graph has a few: joint and axis names)
_CODES = {"boolean": "?", "int8": "b", "uint8": "B", "int16": "h", "uint16": "H", "int32": "i",
          "uint32": "I", "int64": "q", "uint64": "Q", "float": "f", "double": "d"}
_ARRAY_CODES = {"int8": "b", "uint8": "B", "int16": "h", "uint16": "H", "int32": "i", "uint32": "I",
                "int64": "q", "uint64": "Q", "float": "f", "double": "d"}
_U32 = struct.Struct("<I").pack
# per start position modulo 4: the padding to a uint32 and the uint32 (string and sequence lengths)
_COUNT = tuple(struct.Struct("<" + "x" * ((-r) % 4) + "I").pack for r in range(4))
_COUNT_SIZE = tuple((-r) % 4 + 4 for r in range(4))
_PAD4 = tuple(b"\0" * ((-r) % 4) for r in range(4))
# per start position modulo 8: the count of a non-empty sequence of 8-byte elements, padded before
# (to 4) and after (to 8, where the first element starts)
_COUNT8 = tuple(struct.Struct("<" + "x" * ((-r) % 4) + "I" + "x" * ((-(r + (-r) % 4 + 4)) % 8)).pack for r in range(8))
_COUNT8_SIZE = tuple((-r) % 4 + 4 + (-(r + (-r) % 4 + 4)) % 8 for r in range(8))


class Unsupported(TypeError):
    """A field type the generated encoders do not cover."""


# what an encoder raises for a value it cannot pack as rclpy would (e.g. a float32 beyond its range)
ENCODE_ERRORS = (struct.error, TypeError, ValueError, AttributeError, OverflowError)


def _utf8(s: str) -> bytes:
    """A string as rclpy stores it: UTF-8, cut at the first NUL (rosidl assigns C strings)."""
    b = s.encode()
    return b[:b.index(b"\0")] if b"\0" in b else b


def _string_sequence(values) -> bytes:
    """A sequence of strings from a 4-aligned position: count, then per string its padded length,
    the bytes and the NUL (the padding inside does not depend on where it starts)."""
    parts, pos = [_U32(len(values))], 4
    for s in values:
        b = _utf8(s)
        n = len(b) + 1
        parts.append(_COUNT[pos & 3](n))
        parts.append(b)
        parts.append(b"\0")
        pos += _COUNT_SIZE[pos & 3] + n
    return b"".join(parts)


def _raw_sequence(values, code: str, size: int) -> bytes:
    """Elements of a numeric sequence as rclpy copies them: a buffer's bytes (whole elements of
    ``size``), else each element converted."""
    try:
        b = memoryview(values).tobytes()
    except TypeError:
        return bytes(values) if code == "?" else array(code, values).tobytes()
    return b[:len(b) - len(b) % size]


class _Generator:
    """Writes the source of one encoder function; ``pos`` is the position after the CDR header."""

    def __init__(self):
        self.lines: list[str] = []
        self.env: dict = {"_array": array, "_ndarray": np.ndarray, "_F64": np.dtype(np.float64), "_utf8": _utf8, "_strseq": _string_sequence, "_raw": _raw_sequence,
                          "_COUNT": _COUNT, "_COUNT_SIZE": _COUNT_SIZE, "_COUNT8": _COUNT8,
                          "_COUNT8_SIZE": _COUNT8_SIZE, "_PAD4": _PAD4}
        self.indent = 1
        self.names = 0
        self.run: list[tuple[str, int, str]] = []   # pending fixed-size fields: code, size, expression
        self.known: int | None = 0                  # pos modulo 8 where the generator knows it

    def name(self, prefix: str = "_v") -> str:
        self.names += 1
        return f"{prefix}{self.names}"

    def const(self, value) -> str:
        name = self.name("_k")
        self.env[name] = value
        return name

    def emit(self, line: str) -> None:
        self.lines.append("    " * self.indent + line)

    # -- fixed-size fields: collected into one struct call ----------------------------------------
    def flush(self) -> None:
        run, self.run = self.run, []
        if not run:
            return
        args = ", ".join(expr for _, _, expr in run)
        if self.known is not None:
            fmt, size = _run_format(run, self.known)
            self.emit(f"out.append({self.const(struct.Struct(fmt).pack)}({args}))")
            self.emit(f"pos += {size}")
            self.known = (self.known + size) % 8
            return
        align = max(min(size, 8) for _, size, _ in run)  # paddings depend on the start modulo this
        if align == 1:
            fmt, size = _run_format(run, 0)
            self.emit(f"out.append({self.const(struct.Struct(fmt).pack)}({args}))")
            self.emit(f"pos += {size}")
            return
        formats = [_run_format(run, r) for r in range(align)]
        packs = self.const(tuple(struct.Struct(fmt).pack for fmt, _ in formats))
        sizes = self.const(tuple(size for _, size in formats))
        self.emit(f"_r = pos & {align - 1}")
        self.emit(f"out.append({packs}[_r]({args}))")
        self.emit(f"pos += {sizes}[_r]")

    def count(self, n: str, then: str = "") -> None:
        """A uint32 count or string length, aligned to 4, and ``then`` bytes of that many bytes."""
        more = f" + len({then})" if then else ""
        if self.known is not None:
            pad = (-self.known) % 4
            self.emit(f"out.append({self.const(_COUNT[self.known % 4])}({n}))")
            self.emit(f"pos += {pad + 4}{more}")
            self.known = (self.known + pad + 4) % 8
        else:
            self.emit("_r = pos & 3")
            self.emit(f"out.append(_COUNT[_r]({n}))")
            self.emit(f"pos += _COUNT_SIZE[_r]{more}")
        if then:
            self.emit(f"out.append({then})")
            self.known = None

    # -- fields ------------------------------------------------------------------------------------
    def message(self, cls, expr: str) -> None:
        slots = [s for s in cls.__slots__ if s != "_check_fields"]
        if not cls.SLOT_TYPES:                       # rosidl gives empty structures one uint8 member
            self.run.append(("B", 1, "0"))
            return
        for slot, slot_type in zip(slots, cls.SLOT_TYPES):
            self.field(slot_type, f"{expr}.{slot}")

    def field(self, slot_type, expr: str) -> None:
        if isinstance(slot_type, BasicType):
            if slot_type.typename == "octet":        # a bytes object: rclpy takes its first byte
                self.run.append(("B", 1, f"{expr}[0]"))
                return
            code = "B" if slot_type.typename == "char" else _CODES.get(slot_type.typename)
            if code is None:
                raise Unsupported(slot_type.typename)
            self.run.append((code, struct.calcsize(code), f"({expr} is True)" if code == "?" else expr))
        elif isinstance(slot_type, NamespacedType):
            var = self.name()
            self.emit(f"{var} = {expr}")
            self.message(_nested_class(slot_type), var)
        elif isinstance(slot_type, (BoundedString, BoundedSequence)) or (
                isinstance(slot_type, AbstractGenericString) and not isinstance(slot_type, AbstractString)):
            raise Unsupported(repr(slot_type))       # wide strings; bounds that rclpy checks
        elif isinstance(slot_type, AbstractString):
            self.flush()
            b = self.name("_b")
            self.emit(f"{b} = {expr}.encode() + b'\\0'")
            self.emit(f"if {b}.index(0) < len({b}) - 1: {b} = _utf8({expr}) + b'\\0'")
            self.count(f"len({b})", then=b)
        elif isinstance(slot_type, Array):
            self.array(slot_type, expr)
        elif isinstance(slot_type, AbstractSequence):
            self.sequence(slot_type.value_type, expr)
        else:
            raise Unsupported(repr(slot_type))

    def array(self, slot_type: Array, expr: str) -> None:
        value, size = slot_type.value_type, slot_type.size
        var = self.name()
        self.emit(f"{var} = {expr}")
        self.emit(f"if len({var}) != {size}: raise ValueError('array of {size} expected')")
        if isinstance(value, BasicType):
            code = _CODES.get(value.typename)
            if code is None:
                raise Unsupported(value.typename)
            self.run.extend((code, struct.calcsize(code), f"{var}[{i}]") for i in range(size))
            return
        self.flush()
        self.loop(value, var)

    def sequence(self, value, expr: str) -> None:
        self.flush()
        var = self.name()
        self.emit(f"{var} = {expr}")
        if isinstance(value, BasicType) and value.typename in _CODES:
            code = _CODES[value.typename]
            size = struct.calcsize(code)
            b = self.name("_b")
            if code == "?":
                self.emit(f"{b} = bytes({var}) if type({var}) is list else _raw({var}, '?', 1)")
            else:   # inline for what messages and payloads hold (cdpr_control.ros.adapted), else _raw
                ndarray = f" or (_t is _ndarray and {var}.dtype is _F64)" if code == "d" else ""
                self.emit(f"_t = type({var})")
                self.emit(f"{b} = {var}.tobytes() if (_t is _array and {var}.typecode == '{code}'){ndarray} "
                          f"else _array('{code}', {var}).tobytes() if _t is tuple else _raw({var}, '{code}', {size})")
            if size == 8:                             # the elements start 8-aligned, if there are any
                self.emit(f"if {b}:")
                self.emit("    _r = pos & 7")
                self.emit(f"    out.append(_COUNT8[_r](len({b}) >> 3))")
                self.emit(f"    out.append({b})")
                self.emit(f"    pos += _COUNT8_SIZE[_r] + len({b})")
                self.emit("else:")
                self.indent += 1
                self.count("0")
                self.indent -= 1
            else:
                self.count(f"len({b}) // {size}" if size > 1 else f"len({b})", then=b)
        elif isinstance(value, AbstractString) and not isinstance(value, BoundedString):
            cache = self.const({})                   # lists encoded lately (names of joints, axes)
            b = self.name("_b")
            self.emit(f"_key = tuple({var})")
            self.emit(f"{b} = {cache}.get(_key)")
            self.emit(f"if {b} is None:")
            self.emit(f"    {b} = _strseq({var})")
            self.emit(f"    if len({cache}) >= {NAMES_CACHE}: {cache}.clear()")
            self.emit(f"    {cache}[_key] = {b}")
            self.emit("_p = _PAD4[pos & 3]")
            self.emit("out.append(_p)")
            self.emit(f"out.append({b})")
            self.emit(f"pos += len(_p) + len({b})")
        elif isinstance(value, (NamespacedType, Array, AbstractSequence)) or isinstance(value, AbstractString):
            if isinstance(value, BoundedString):
                raise Unsupported(repr(value))
            self.count(f"len({var})")
            self.loop(value, var)
        else:
            raise Unsupported(repr(value))
        self.known = None

    def loop(self, value, var: str) -> None:
        """Each element of ``var`` (a sequence or array), at a position known only at run time."""
        element = self.name("_e")
        self.emit(f"for {element} in {var}:")
        self.indent += 1
        self.known = None
        self.field(value, element)
        self.flush()
        self.emit("pass")
        self.indent -= 1
        self.known = None


def _run_format(run: list[tuple[str, int, str]], start: int) -> tuple[str, int]:
    """struct format (with padding bytes) of fixed-size fields starting at ``start``, and its size."""
    fmt, pos = "<", start
    for code, size, _ in run:
        pad = (-pos) % min(size, 8)
        fmt += "x" * pad + code
        pos += pad + size
    return fmt, pos - start


@functools.lru_cache(maxsize=None)
def encoder(cls: type) -> Callable[[object], bytes] | None:
    """``f(msg) -> bytes``: the CDR encoding of a message of class ``cls`` or its payload (header
    included, no trailing padding), or None for a type with fields it does not cover."""
    gen = _Generator()
    try:
        gen.message(cls, "m")
    except Unsupported:
        return None
    gen.flush()
    source = "\n".join(["def encode(m):", "    out = [_HEADER]", "    pos = 0", *gen.lines,
                        "    return b''.join(out)"])
    env = dict(gen.env, _HEADER=HEADER)
    name = f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"
    exec(compile(source, f"<cdr encoder of {name}>", "exec"), env)  # noqa: S102 - from the type's layout
    encode = env["encode"]
    encode.__doc__ = f"CDR encoding of a {name} (cdpr_control.ros.cdr)."
    return encode


def _nested_class(slot_type: NamespacedType) -> type:
    """The generated class of a nested message field (as the generated constructor imports it)."""
    *package, name = slot_type.namespaced_name()
    return getattr(importlib.import_module(".".join(package)), name)


def to_bytes(obj, cls: type) -> bytes | None:
    """The CDR bytes of ``obj``, a message of class ``cls`` or its payload; None where rclpy must
    serialize it (no encoder for the type, or a value it cannot pack as rclpy would)."""
    encode = encoder(cls)
    if encode is None:
        return None
    try:
        return encode(obj)
    except ENCODE_ERRORS:
        return None

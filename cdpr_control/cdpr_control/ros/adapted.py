"""Type adaptation in the spirit of REP 2007 (rclcpp's ``TypeAdapter``): payloads inside the process.

The nodes of a composed graph hand their stage's output to each other as a *payload*, not as a
ROS message: an immutable object of a class generated per message type (:func:`payload_class`)
with the message's fields: the float64 sequences a stage computed as numpy arrays (f, q, theta,
the controllers' outputs) as read-only numpy arrays, those given as lists as tuples, every other
field (header with stamp and frame, names, nested messages) as given. The ROS message is built
from it only when it must leave the process or a subscriber asks for one, at most once per
publication (:meth:`Payload.to_msg`, lazily, cached on the payload):

- ``IntraProcessPublisher.publish`` (intraprocess.py) takes a payload of the publisher's type like
  a message; local subscriptions created with ``adapted=True`` receive the payload itself, every
  other local subscription (a user's node composed with the graph, the ordinary rclpy API) the
  message, and DDS the message when a subscriber outside the process matches;
- a payload reads like its message: ``p.position``, ``p.header.stamp``, ``len(p.f)``, and its
  slots are the message's (``p._position``), so ``StampSync``'s checks, ``sync.stamp_ns`` and the
  bag recorder's CDR encoders (cdpr_tools.bag.encode, generated from the message layout) take
  either. An ``adapted`` callback must therefore only read fields, which holds for a message too;
- payload and message compare equal when the message built from the payload equals the other.

A publisher may also attach to a payload the values its subscribers convert its nested messages
to (:func:`attach_values`, read-only arrays; :func:`attached_values` reads them): the set-point's
x_d, ẋ_d, ẍ_d, which nine nodes read (:func:`cdpr_control.ros.conversions.setpoint_from_msg`), are
converted once per publication rather than once per subscriber. The message built from the payload
is the same; a subscriber in another process converts it itself, to the same numbers.

So the cable forces f go from the simulator to the joint command as the numpy arrays the stages
compute, where the message path converts them between ``array.array`` and numpy on each of the
four hops (issue 26). The arrays are copies taken at construction (the publisher keeps its own)
and read-only, because every subscriber shares them.

``CDPR_TYPE_ADAPT=0`` in the environment (or :func:`set_enabled` before the nodes are built)
selects the message path of before: :func:`factory` then hands the nodes a message builder taking
the same keyword arguments, and nothing else changes, so both paths are measured side by side
(benchmarks/bench_graph.py).
"""
from __future__ import annotations

import array
import keyword
import operator
import os

import numpy as np
from rosidl_parser.definition import AbstractSequence, BasicType, BoundedSequence

from cdpr_control.ros.message_builders import builder

ENV = "CDPR_TYPE_ADAPT"     # "0": nodes publish ROS messages (the message path before type adaptation)
_state = {"enabled": os.environ.get(ENV, "1") != "0"}
_MISSING = object()
_FLOAT64 = np.dtype(np.float64)
_classes: dict[type, type | None] = {}
_baselines: dict[type, object] = {}


def enabled() -> bool:
    """Whether nodes built now publish payloads (``CDPR_TYPE_ADAPT``, default on)."""
    return _state["enabled"]


def set_enabled(on: bool) -> None:
    """Payloads on or off for the nodes built from now on (the benchmark's two paths in one run)."""
    _state["enabled"] = bool(on)


class Payload:
    """Base of the generated payload classes: ``msg_type`` is the ROS message class it stands for."""

    # rosidl field names never end in "_": no clash with a field
    __slots__ = ("_adapted_msg_", "_adapted_values_")
    msg_type: type = type(None)

    def to_msg(self):
        """The ordinary ROS message with this payload's values, built on the first call, then the same."""
        msg = self._adapted_msg_
        if msg is None:
            msg = self._adapted_msg_ = self._build()
        return msg

    def _build(self):
        raise NotImplementedError   # generated per class by payload_class

    def __eq__(self, other) -> bool:
        if isinstance(other, Payload):
            other = other.to_msg()
        return self.to_msg() == other

    __hash__ = None

    def __repr__(self) -> str:
        return f"payload of {self.to_msg()!r}"

    @classmethod
    def get_fields_and_field_types(cls) -> dict:
        return cls.msg_type.get_fields_and_field_types()


def attach_values(obj, values) -> None:
    """Attach to the payload ``obj``, before it is published, ``values``: what its subscribers would
    convert its fields to, the same numbers, as read-only arrays (every subscriber shares them). A
    message (type adaptation off) is left as it is: its subscribers convert it themselves."""
    if isinstance(obj, Payload):
        obj._adapted_values_ = values


def attached_values(obj):
    """The values :func:`attach_values` attached to ``obj``, None for a payload without them or a message."""
    return obj._adapted_values_ if isinstance(obj, Payload) else None


def as_message(obj):
    """``obj`` as a ROS message: a payload's message, anything else as it is."""
    return obj.to_msg() if isinstance(obj, Payload) else obj


def read_only(values, field: str = "value"):
    """What a payload keeps of a float64 sequence: of a numpy array a read-only float64 copy (the
    array over an immutable ``bytes`` copy, read-only without setting the flag, which costs twice as
    much), of a list or tuple of numbers a tuple (converting the few numbers a node lists to an array
    would cost more than every reader's ``np.asarray`` of them)."""
    if type(values) is tuple:
        return values           # (a received payload's tuple passed on: immutable)
    if type(values) is not np.ndarray:
        if type(values) is list:
            return tuple(values)
        values = np.asarray(values, dtype=np.float64)
    elif type(values.base) is bytes and values.ndim == 1 and values.dtype is _FLOAT64:
        return values           # one of these already (a received payload's array passed on): immutable
    if values.ndim != 1:
        raise ValueError(f"{field}: a 1-D sequence of numbers expected, got shape {values.shape}")
    return np.frombuffer(values.tobytes() if values.dtype is _FLOAT64 else values.astype(np.float64).tobytes())


def _float64_sequence(slot_type) -> bool:
    return (isinstance(slot_type, AbstractSequence) and not isinstance(slot_type, BoundedSequence)
            and isinstance(slot_type.value_type, BasicType) and slot_type.value_type.typename == "double")


def payload_class(cls) -> type | None:
    """The payload class of message class ``cls`` (generated once per class from its definition), or
    None for a class with a field name that is a Python keyword (it has no keyword constructor) or
    a name of :class:`Payload`'s own (``msg_type``, ``to_msg``)."""
    if cls in _classes:
        return _classes[cls]
    names = list(cls.get_fields_and_field_types())
    clash = any(keyword.iskeyword(n) or hasattr(Payload, n) for n in names)   # e.g. a field "to_msg"
    made = None if clash else _generate(cls, names)
    _classes[cls] = made
    return made


def _generate(cls, names: list[str]) -> type:
    default = cls(check_fields=False)
    env: dict = {"_MISSING": _MISSING, "_ro": read_only, "_array": array.array, "_ndarray": np.ndarray,
                 "_b": builder(cls)}
    init, build = ["    self._adapted_msg_ = self._adapted_values_ = None"], ["    _kw = {}"]
    for name, slot_type in zip(names, cls.SLOT_TYPES):
        env[f"_d_{name}"] = (read_only((), name) if _float64_sequence(slot_type)
                             else getattr(default, name))          # shared: nobody modifies a payload
        if _float64_sequence(slot_type):
            init.append(f"    self._{name} = _d_{name} if {name} is _MISSING else _ro({name}, {name!r})")
            given = (f"_array('d', self._{name}.tobytes() if type(self._{name}) is _ndarray "
                     f"else self._{name})")                         # what the generated setter stores
        else:
            init.append(f"    self._{name} = _d_{name} if {name} is _MISSING else {name}")
            given = f"self._{name}"
        # a field not given gets a fresh default from the message builder, never the shared one
        build.append(f"    if self._{name} is not _d_{name}: _kw[{name!r}] = {given}")
    params = f"*, {', '.join(f'{n}=_MISSING' for n in names)}" if names else ""
    source = "\n".join([f"def __init__(self{', ' + params if params else ''}):", *init, "",
                        "def _build(self):", *build, "    return _b(**_kw)"])
    exec(source, env)                               # noqa: S102 - source built from the message definition only
    body = {"__slots__": tuple(f"_{n}" for n in names), "msg_type": cls, "__init__": env["__init__"],
            "_build": env["_build"], "__module__": __name__,
            "__doc__": f"Payload of a {cls.__module__.split('.')[0]}/{cls.__name__} (cdpr_control.ros.adapted): "
                       "its fields, float64 sequences as read-only numpy arrays or tuples."}
    body.update({n: property(operator.attrgetter(f"_{n}")) for n in names})
    return type(f"{cls.__name__}Payload", (Payload,), body)


def payload_of(msg) -> Payload:
    """The payload standing for message ``msg`` (tests, tools: a node builds its payloads directly)."""
    cls = payload_class(type(msg))
    if cls is None:
        raise TypeError(f"{type(msg).__name__} has no payload class (a field named like a keyword or a Payload attribute)")
    return cls(**{name: getattr(msg, name) for name in type(msg).get_fields_and_field_types()})


def factory(cls):
    """What a node builds its output on a topic of type ``cls`` with, from keyword arguments named like
    the fields (float64 sequences as numpy arrays or lists): the payload class, or with type adaptation
    off (or for a class without payloads) a builder of the ROS message converting arrays to lists."""
    made = payload_class(cls) if enabled() else None
    return made if made is not None else baseline(cls)


def baseline(cls):
    """The message builder :func:`factory` hands out with type adaptation off: the same keyword
    arguments, numpy arrays given for float64 sequences converted to lists (as the nodes did)."""
    made = _baselines.get(cls)
    if made is None:
        build = builder(cls)
        arrays = tuple(n for n, t in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES) if _float64_sequence(t))

        def made(**fields):
            for name in arrays:
                value = fields.get(name)
                if type(value) is np.ndarray:
                    fields[name] = value.tolist()
            return build(**fields)
        made.__name__ = f"message_{cls.__name__}"
        _baselines[cls] = made
    return made

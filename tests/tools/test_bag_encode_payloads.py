"""The recorder encodes payloads (cdpr_control.ros.adapted) without building their messages: the CDR
of a payload is the CDR of the message it stands for, byte for byte, and rclpy's serialization of
that message (up to FastCDR's stale alignment padding, zero in ours: test_bag_encode.py), for every
type the graph records, random values, empty and long sequences, strings of every length modulo 4."""
from __future__ import annotations

import random
from array import array

import numpy as np
import pytest
from rosidl_parser.definition import AbstractSequence, BasicType
from test_bag_encode import GRAPH_TYPES, check_same_encoding, fill

from cdpr_control.ros.adapted import payload_class, payload_of
from cdpr_tools.bag.encode import encoder
from cdpr_tools.message_convert import message_class


def with_long_sequences(msg, rng: random.Random, n: int):
    """``msg`` with each float64 sequence of its top level ``n`` random values long (f, q, theta ...)."""
    for name, slot_type in zip(type(msg).get_fields_and_field_types(), type(msg).SLOT_TYPES):
        if isinstance(slot_type, AbstractSequence) and isinstance(slot_type.value_type, BasicType) \
                and slot_type.value_type.typename == "double":
            setattr(msg, name, [rng.uniform(-1e6, 1e6) for _ in range(n)])
    return msg


@pytest.mark.parametrize("type_name", GRAPH_TYPES)
def test_a_payload_encodes_as_its_message(type_name):
    cls, encode = message_class(type_name), encoder(type_name)
    assert payload_class(cls) is not None
    rng = random.Random(type_name)
    messages = [cls(), *(fill(cls, rng) for _ in range(40)),
                *(with_long_sequences(fill(cls, rng), rng, n) for n in (0, 1, 7, 1000))]
    for msg in messages:
        as_lists = {n: (v.tolist() if isinstance(v, array) else v)    # float64 sequences given as lists: tuples
                    for n, v in ((n, getattr(msg, n)) for n in cls.get_fields_and_field_types())}
        for payload in (payload_of(msg), payload_class(cls)(**as_lists)):
            ours = encode(payload)
            assert payload._adapted_msg_ is None       # encoded from the payload, no message built
            assert ours == encode(msg)
            check_same_encoding(msg, ours)
            assert payload.to_msg() == msg


def test_a_payload_from_the_stages_arrays_encodes_as_the_message_of_their_lists():
    """What a node publishes: numpy arrays (views, other dtypes) into the payload, lists into the message."""
    from sensor_msgs.msg import JointState
    theta = np.arange(16.0)[::2] * 0.1                 # a strided view
    effort = np.arange(8, dtype=np.float32)            # converted to float64 as the message's setter does
    payload = payload_class(JointState)(name=["cable_1", "c2"], position=theta, effort=effort)
    msg = JointState(name=["cable_1", "c2"], position=theta.tolist(), effort=effort.astype(float).tolist())
    check_same_encoding(msg, encoder("sensor_msgs/msg/JointState")(payload))
    assert payload.to_msg() == msg

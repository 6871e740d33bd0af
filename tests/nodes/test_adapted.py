"""Type adaptation (cdpr_control.ros.adapted): nodes of one process pass payloads (arrays and stamp),
the ROS message is built only for whoever needs one, once per publication, and is an ordinary message."""
from __future__ import annotations

from unittest import mock

import numpy as np
import pytest
from cdpr_msgs.msg import CableForces, ControllerState
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from test_intraprocess import DEEP, joint_state, spaces, wait_for  # noqa: F401 (fixture)

from cdpr_control.ros import adapted, cdr
from cdpr_control.ros.adapted import Payload, as_message, payload_class, payload_of
from cdpr_control.ros.intraprocess import IntraProcess, IntraProcessNode
from cdpr_control.ros.message_builders import builder
from cdpr_control.ros.sync import input_problem


def cable_forces(f) -> Payload:
    header = builder(JointState)().header
    header.stamp.sec, header.frame_id = 7, "base"
    return payload_class(CableForces)(header=header, f=f, f_min=[1.0, 1.0], f_max=[40.0, 40.0])


def test_a_payload_reads_like_its_message_and_cannot_be_changed():
    f = np.array([10.0, 20.5])
    p = cable_forces(f)
    f[0] = -1.0                                     # the publisher's array stays its own
    assert p.f.tolist() == [10.0, 20.5] and p.header.stamp.sec == 7
    assert p.f_min == (1.0, 1.0)                    # a list given: kept as a tuple (immutable too)
    assert len(p.f) == 2 and p._f is p.f            # the message's slots, for the encoders and StampSync
    with pytest.raises(ValueError):
        p.f[1] = 0.0                                # read-only arrays: every subscriber shares them
    with pytest.raises(AttributeError):
        p.f = [1.0]


def test_the_message_of_a_payload_is_ordinary_built_once_and_independent():
    p = cable_forces([10.0, 20.5])
    msg = p.to_msg()
    assert type(msg) is CableForces and msg is p.to_msg()
    assert msg == CableForces(header=p.header, f=[10.0, 20.5], f_min=[1.0, 1.0], f_max=[40.0, 40.0])
    assert p == msg and p == cable_forces([10.0, 20.5]) and p != cable_forces([10.0, 20.0])
    msg.f[0] = 99.0                                 # a user may change their message: not the payload
    assert p.f[0] == 10.0
    # a field not given gets the .msg default, fresh in the message (not an object shared with others)
    state = payload_class(ControllerState)(output=[1.0])
    assert state.to_msg() == ControllerState(output=[1.0])
    assert state.to_msg().header is not payload_class(ControllerState)(output=[1.0]).to_msg().header


def test_payload_of_a_message_stands_for_it():
    msg = joint_state(3)
    assert payload_of(msg).to_msg() == msg and payload_of(msg).position.dtype == np.float64


def test_bad_values_are_refused_with_the_field_named():
    with pytest.raises(ValueError, match="f: a 1-D sequence"):
        cable_forces(np.zeros((2, 2)))
    with pytest.raises(TypeError):
        payload_class(CableForces)(force=[1.0])    # no such field


def test_a_received_payload_passed_on_is_not_copied_again():
    p = cable_forces([1.0, 2.0])
    assert payload_class(ControllerState)(reference=p.f).reference is p.f


def test_the_input_checks_take_payloads_like_messages():
    assert input_problem(cable_forces([10.0, 20.0]), 2) is None
    assert input_problem(cable_forces([10.0, float("nan")]), 2) == "f has non-finite values"
    assert input_problem(cable_forces([10.0]), 2) == "f has 1 values, the robot has 2 cables"


def test_the_factory_gives_payloads_or_with_type_adaptation_off_the_messages(monkeypatch):
    made = adapted.factory(JointState)(name=["a"], position=np.array([1.5]))
    assert isinstance(made, Payload)
    monkeypatch.setitem(adapted._state, "enabled", False)
    made = adapted.factory(JointState)(name=["a"], position=np.array([1.5]))
    assert type(made) is JointState and made.position.tolist() == [1.5]


def test_publish_hands_payloads_to_adapted_subscribers_and_one_message_to_the_others(spaces):
    graph = spaces()
    pub_node, sub_node = graph.node("adapt_pub"), graph.node("adapt_sub")
    publisher = pub_node.create_publisher(JointState, "/adapt/state", DEEP)
    payloads, messages, more_messages, raw = [], [], [], []
    sub_node.create_subscription(JointState, "/adapt/state", payloads.append, DEEP, adapted=True)
    sub_node.create_subscription(JointState, "/adapt/state", messages.append, DEEP)
    sub_node.create_subscription(JointState, "/adapt/state", more_messages.append, DEEP)
    sub_node.create_subscription(JointState, "/adapt/state", raw.append, DEEP, raw=True)
    graph.start()
    sent = [payload_of(joint_state(k)) for k in range(5)]
    for p in sent:
        publisher.publish(p)
    wait_for(lambda: len(payloads) == len(messages) == len(more_messages) == len(raw) == 5, "5 deliveries each")
    assert all(a is b for a, b in zip(payloads, sent))
    assert all(type(m) is JointState and m == joint_state(k) for k, m in enumerate(messages))
    assert all(a is b for a, b in zip(messages, more_messages))          # built once per publication
    assert [deserialize_message(b, JointState) for b in raw] == [joint_state(k) for k in range(5)]


def test_no_message_is_built_while_only_adapted_subscribers_take_the_topic(spaces):
    graph = spaces()
    publisher = graph.node("adapt_only_pub").create_publisher(JointState, "/adapt/only", DEEP)
    got = []
    graph.node("adapt_only_sub").create_subscription(JointState, "/adapt/only", got.append, DEEP, adapted=True)
    graph.start()
    p = payload_of(joint_state(1))
    publisher.publish(p)
    wait_for(lambda: got, "the payload")
    assert got[0] is p and p._adapted_msg_ is None


@pytest.mark.parametrize("encoded", [True, False], ids=["cdr_from_the_payload", "rclpy_fallback"])
def test_a_node_outside_the_process_gets_the_message_over_dds(spaces, encoded):
    """Outside, the ordinary message arrives; it left as CDR bytes encoded from the payload (no message
    built, rclpy's publish not called), or through rclpy where cdr.py cannot encode a value."""
    inside, outside = spaces(), spaces()
    publisher = inside.node("adapt_dds_pub").create_publisher(JointState, "/adapt/dds", DEEP)
    local, remote = [], []
    inside.node("adapt_dds_local").create_subscription(JointState, "/adapt/dds", local.append, DEEP, adapted=True)
    outside.node("adapt_dds_remote", cls=Node).create_subscription(JointState, "/adapt/dds", remote.append, DEEP)
    inside.start()
    outside.start()
    wait_for(lambda: publisher.get_subscription_count() >= 2, "discovery")
    sent = [payload_of(joint_state(k)) for k in range(3)]
    with mock.patch.object(cdr, "to_bytes", side_effect=cdr.to_bytes if encoded else lambda obj, cls: None), \
            mock.patch.object(Publisher, "publish", autospec=True, side_effect=Publisher.publish) as rclpy_publish:
        for p in sent:
            publisher.publish(p)
    wait_for(lambda: len(remote) == 3 and len(local) == 3, "3 messages inside and outside")
    assert remote == [joint_state(k) for k in range(3)]
    assert all(isinstance(p, Payload) for p in local)
    rclpy_calls = [call for call in rclpy_publish.call_args_list if call.args[0] is publisher]
    if encoded:
        assert not rclpy_calls and all(p._adapted_msg_ is None for p in sent)   # nothing built for DDS
    else:
        assert len(rclpy_calls) == 3


def test_without_intra_process_delivery_nodes_build_messages(spaces):
    graph = spaces()
    IntraProcess.set_enabled(graph.context, False)
    node = graph.node("adapt_off")
    assert node.message_factory(JointState) is adapted.baseline(JointState)
    assert isinstance(graph.node("adapt_on", cls=IntraProcessNode).message_factory(CableForces)(), CableForces)
    assert as_message(node.message_factory(JointState)()) == JointState()

"""Every cdpr_msgs type crosses rclpy: messages are published and received, services answered,
the action runs with feedback and result; all fields survive the round trip."""
import importlib
import re
import time
from pathlib import Path

import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from rclpy.action import ActionClient, ActionServer  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402

MSGS_DIR = Path(__file__).resolve().parents[2] / "cdpr_msgs"


def _interfaces(kind: str) -> list[str]:
    return sorted(p.stem for p in (MSGS_DIR / kind).glob(f"*.{kind}"))


def _value(type_name: str, i: int):
    """A deterministic non-default value of a ROS field type."""
    seq = re.fullmatch(r"sequence<(.+?)(?:, \d+)?>", type_name)
    if seq:
        return [_value(seq.group(1), i + k) for k in range(3)]
    arr = re.fullmatch(r"(.+)\[(\d+)\]", type_name)
    if arr:
        return [_value(arr.group(1), i + k) for k in range(int(arr.group(2)))]
    if type_name in ("double", "float"):
        return 0.5 + i
    if type_name == "boolean":
        return True
    if type_name.startswith("string") or type_name.startswith("wstring"):
        return f"value {i}"
    if re.fullmatch(r"u?int\d+|octet|byte|char", type_name):
        return (i % 5) + 1
    return _filled(_class(type_name), i)


def _class(type_name: str):
    pkg, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def _filled(cls, i: int = 1):
    msg = cls()
    for k, (field, type_name) in enumerate(cls.get_fields_and_field_types().items()):
        value = _value(type_name, i + k)
        if field == "stamp" or type_name == "builtin_interfaces/Time":
            value = type(getattr(msg, field))(sec=i + k, nanosec=1000 * k)
        setattr(msg, field, value)
    return msg


def _spin_until(executor, done, timeout=120.0):   # a hang guard, not a margin (busy machines)
    deadline = time.monotonic() + timeout
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    return done()


@pytest.fixture(scope="module")
def node():
    rclpy.init()
    node = rclpy.create_node("cdpr_msgs_roundtrip")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    node.executor_ = executor
    yield node
    node.destroy_node()
    rclpy.shutdown()


def test_interface_lists_are_complete():
    assert len(_interfaces("msg")) >= 6 and len(_interfaces("srv")) >= 3 and _interfaces("action")


@pytest.mark.parametrize("name", _interfaces("msg"))
def test_message_published_and_received(node, name):
    cls = getattr(importlib.import_module("cdpr_msgs.msg"), name)
    sent = _filled(cls)
    received = []
    sub = node.create_subscription(cls, f"roundtrip_{name}", received.append, 10)
    pub = node.create_publisher(cls, f"roundtrip_{name}", 10)
    try:
        assert _spin_until(node.executor_, lambda: pub.get_subscription_count() > 0)
        pub.publish(sent)
        assert _spin_until(node.executor_, lambda: received), f"{name} not received"
        assert received[0] == sent
    finally:
        node.destroy_publisher(pub)
        node.destroy_subscription(sub)


@pytest.mark.parametrize("name", _interfaces("srv"))
def test_service_called_and_answered(node, name):
    srv = getattr(importlib.import_module("cdpr_msgs.srv"), name)
    request, response = _filled(srv.Request, 2), _filled(srv.Response, 3)
    seen = []

    def handle(req, resp):
        seen.append(req)
        return response

    server = node.create_service(srv, f"roundtrip_{name}", handle)
    client = node.create_client(srv, f"roundtrip_{name}")
    try:
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(request)
        assert _spin_until(node.executor_, future.done)
        assert seen[0] == request and future.result() == response
    finally:
        node.destroy_client(client)
        node.destroy_service(server)


@pytest.mark.parametrize("name", _interfaces("action"))
def test_action_goal_feedback_result(node, name):
    action = getattr(importlib.import_module("cdpr_msgs.action"), name)
    goal, feedback, result = _filled(action.Goal, 1), _filled(action.Feedback, 2), _filled(action.Result, 3)
    seen_feedback = []

    def execute(goal_handle):
        assert goal_handle.request == goal
        goal_handle.publish_feedback(feedback)
        goal_handle.succeed()
        return result

    server = ActionServer(node, action, f"roundtrip_{name}", execute)
    client = ActionClient(node, action, f"roundtrip_{name}")
    try:
        assert client.wait_for_server(timeout_sec=5.0)
        sent = client.send_goal_async(goal, feedback_callback=lambda m: seen_feedback.append(m.feedback))
        assert _spin_until(node.executor_, sent.done) and sent.result().accepted
        done = sent.result().get_result_async()
        assert _spin_until(node.executor_, done.done)
        assert done.result().result == result
        assert _spin_until(node.executor_, lambda: seen_feedback) and seen_feedback[0] == feedback
    finally:
        client.destroy()
        server.destroy()

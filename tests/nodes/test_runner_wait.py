"""runner.spin's wait on a SingleThreadedExecutor (runner._wait): DDS messages and plain timer callbacks
are dispatched without the executor's turn; services, coroutine timers, callbacks that take the message
info and the executor's tasks still get it."""
from __future__ import annotations

import threading
import time

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.task import Future
from rclpy.node import Node
from std_msgs.msg import Int64
from std_srvs.srv import Trigger

from cdpr_control.ros import runner
from cdpr_tools.ros_graph import new_context
from test_intraprocess import TIMEOUT, wait_for  # (the same folder's helpers)

DEEP = 1000


@pytest.fixture
def spun():
    """A node on a SingleThreadedExecutor spun by runner.spin in a thread, the executor's wait-set
    builds counted (each turn of it, through spin_once or runner._run_ready, asks for its ready
    callbacks), and a publisher node in a context of its own (DDS between them)."""
    turns = []
    inside, outside = new_context(), new_context()
    node = Node("wait_inside", context=inside)
    other = Node("wait_outside", context=outside)
    executor = SingleThreadedExecutor(context=inside)
    real = executor.wait_for_ready_callbacks
    executor.wait_for_ready_callbacks = lambda *args, **kwargs: (turns.append(1), real(*args, **kwargs))[1]
    executor.add_node(node)
    stop = threading.Event()
    thread = threading.Thread(target=runner.spin, args=(executor, stop), daemon=True)
    yield node, other, executor, thread, turns
    stop.set()
    thread.join(5)
    node.destroy_node(), other.destroy_node()
    inside.try_shutdown(), outside.try_shutdown()


def test_messages_are_dispatched_without_the_executors_turn(spun):
    node, other, executor, thread, turns = spun
    plain, with_info = [], []
    node.create_subscription(Int64, "/wait/plain", lambda msg: plain.append(msg.data), DEEP)
    node.create_subscription(Int64, "/wait/info", lambda msg, info: with_info.append((msg.data, info)), DEEP)
    thread.start()
    pub, pub_info = other.create_publisher(Int64, "/wait/plain", DEEP), other.create_publisher(Int64, "/wait/info", DEEP)
    wait_for(lambda: pub.get_subscription_count() == 1 and pub_info.get_subscription_count() == 1, "discovery")
    pub.publish(Int64(data=-1))          # (start-up: the executor's guard, triggered by add_node, had its turn)
    wait_for(lambda: plain == [-1], "the first message")
    before = len(turns)
    for k in range(50):
        pub.publish(Int64(data=k))
    wait_for(lambda: len(plain) == 51, lambda: f"50 messages, got {len(plain) - 1}")
    assert plain == [-1, *range(50)]
    assert len(turns) == before          # no turn of the executor for the plain subscription's messages
    for k in range(3):
        pub_info.publish(Int64(data=k))
    wait_for(lambda: len(with_info) == 3, lambda: f"3 messages with their info, got {len(with_info)}")
    assert [k for k, _ in with_info] == [0, 1, 2] and all("source_timestamp" in info for _, info in with_info)
    assert len(turns) > before           # the executor's way for a callback that takes the info


def test_timers_run_without_the_executors_turn(spun):
    """Between two slices of a lockstep ring and while waiting, a plain timer callback is called here:
    the watch timers of the nodes' stamp syncs expire every slice and made every slice a turn."""
    node, other, executor, thread, turns = spun
    ticks = []
    node.create_timer(0.01, lambda: ticks.append(1))
    thread.start()
    wait_for(lambda: len(ticks) >= 3, lambda: f"the timer to tick 3 times, ticked {len(ticks)}")
    before, ticked = len(turns), len(ticks)
    wait_for(lambda: len(ticks) >= ticked + 10, lambda: f"the timer to tick 10 times more, ticked {len(ticks) - ticked}")
    assert len(turns) == before


def test_services_coroutine_timers_and_tasks_get_the_executors_turn(spun):
    node, other, executor, thread, turns = spun
    ticks = []

    async def tick():
        ticks.append(1)
    node.create_timer(0.01, tick)
    node.create_service(Trigger, "/wait/trigger", lambda request, response: (
        setattr(response, "success", True), response)[1])
    done = []

    async def task():
        done.append(1)
    thread.start()
    wait_for(lambda: len(ticks) >= 5, lambda: f"the coroutine timer to tick 5 times, ticked {len(ticks)}")
    client = other.create_client(Trigger, "/wait/trigger")
    assert client.wait_for_service(timeout_sec=TIMEOUT)
    future = client.call_async(Trigger.Request())
    other_executor = SingleThreadedExecutor(context=other.context)
    other_executor.add_node(other)
    other_executor.spin_until_future_complete(future, timeout_sec=TIMEOUT)
    assert future.done() and future.result().success
    executor.create_task(task)           # wakes the executor's guard condition
    wait_for(lambda: done, "the task to run")


def test_a_task_in_progress_is_polled(spun):
    """A task that awaits a future (an action's execute coroutine awaiting its program) goes on only
    when a turn of the executor polls it: setting the future triggers nothing. The lockstep ring's
    slices and the timers that expire meanwhile must not leave it waiting (a program's result never
    reached its client)."""
    node, other, executor, thread, turns = spun
    ticks, done = [], []
    node.create_timer(0.01, lambda: ticks.append(1))
    result = Future()

    async def execute():
        done.append(await result)
    thread.start()
    executor.create_task(execute)
    wait_for(lambda: len(ticks) >= 3, lambda: f"the timer to tick 3 times, ticked {len(ticks)}")
    result.set_result("finished")       # (from this thread, without an executor: no guard is triggered)
    wait_for(lambda: done == ["finished"], "the task to finish")

"""Running nodes: the executor loop and the ``main()`` of a node module.

``rclpy.experimental.EventsExecutor`` (about 17 us a hop here, against 300 us for the
SingleThreadedExecutor) has a ``spin()`` and ``spin_until_future_complete()`` that, in the rclpy
7.1.x wheels, hold the GIL and never dispatch a callback; ``spin_once()`` works. So every loop in
the project spins with :func:`spin`, which also gives it a stop flag and lets Ctrl-C through.
(Its subscriptions also take one-argument callbacks only: a ``(msg, info)`` callback raises
``SystemError: null argument to internal routine``.)
"""
from __future__ import annotations

import contextlib
import inspect
import signal
import threading
from typing import Iterator

import rclpy
from rclpy.exceptions import InvalidHandle
from rclpy.executors import Executor, ExternalShutdownException, ShutdownException, TimeoutException
from rclpy.experimental import EventsExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from rclpy.waitable import NumberOfEntities

from cdpr_control.ros.intraprocess import IntraProcess

SPIN_PERIOD = 0.1  # s: longest time between checks of the stop flag


def spin(executor, stop: threading.Event | None = None) -> None:
    """Run callbacks until ``stop`` is set or the executor's context shuts down; in-process
    deliveries left over by a chain that ran out of its time budget continue between events. An
    rclpy Executor's nodes wait for their next input in :func:`_wait` (without waiting where a chain
    is queued: between two of its slices)."""
    context = executor.context
    registry = IntraProcess.of(context)
    registry.owner = threading.get_ident()  # in-process deliveries from other threads wake this one
    registry.pumped = True                  # a long in-process chain continues between events here
    try:
        while context.ok() and not (stop is not None and stop.is_set()):
            try:
                pending = registry.pending()
                if isinstance(executor, Executor):
                    _wait(executor, 0.0 if pending else SPIN_PERIOD)
                else:
                    executor.spin_once(timeout_sec=0.0 if pending else SPIN_PERIOD)
            except ExternalShutdownException:
                return
            if registry.pending():
                registry.pump()
    finally:
        registry.owner = None
        registry.pumped = False


def _run_ready(executor: Executor) -> None:
    """One wait of ``executor`` and every callback it found ready, between two slices of an in-process
    chain. (``spin_once`` runs one callback a call: with the chain's slices in between, a service
    request queued behind a few timers waited 250 ms instead of 35.)"""
    while True:
        try:
            handler, _, _ = executor.wait_for_ready_callbacks(timeout_sec=0.0)
        except (TimeoutException, ShutdownException):
            return
        handler()
        if handler.exception() is not None:
            raise handler.exception()


def _wait(executor: Executor, timeout_sec: float) -> None:
    """Wait up to ``timeout_sec`` for the next input of ``executor``'s nodes and run it: DDS messages are
    taken and handed to their subscriptions' callbacks, and expired timers' plain callbacks called,
    here; a ready service, client, guard condition or waitable (an action server), a coroutine timer,
    a callback that takes the message info, or a task in progress (an action's execute coroutine,
    which only a turn polls) gets a turn of the executor, which finds them ready again.

    A turn of a SingleThreadedExecutor builds its wait set in Python over every entity of every node
    and dispatches each ready callback through a task (1.5-2.4 ms for closed_loop.yaml's nodes,
    docs/performance.md). A composed lockstep graph waits so between every two 50 ms slices of its
    ring (where its nodes' stamp-sync watch timers have expired), and for every period's winch state
    where it is fed over DDS (its simulator or drives in another process): this wait adds the
    entities' handles to an rcl wait set directly. (rclpy 7.1 has no per-entity ready callbacks
    outside its EventsExecutor, whose timers starve beside a lockstep ring.)
    """
    nodes = executor.get_nodes()
    subscriptions = [s for node in nodes for s in node.subscriptions]
    timers = [t for node in nodes for t in node.timers]
    services = [s for node in nodes for s in node.services]
    clients = [c for node in nodes for c in node.clients]
    # the executor's own guard condition too: triggered when a task it runs (an action's execute
    # coroutine) can go on, or a node is added; the turn then runs it
    guards = [g for node in nodes for g in node.guards] + [g for g in (getattr(executor, "_guard", None),) if g]
    waitables = [w for node in nodes for w in node.waitables]
    entered = []                            # (each handle stays valid while it is in the wait set)

    def valid(entities: list, handle=lambda e: e.handle) -> list:
        kept = []
        for entity in entities:
            h = handle(entity)
            try:
                h.__enter__()               # (directly: through contextlib's ExitStack, a quarter of this wait)
            except InvalidHandle:           # destroyed meanwhile (as the executor skips it)
                continue
            entered.append(h)
            kept.append(entity)
        return kept
    try:
        subscriptions, timers, services, clients, guards = (valid(e) for e in (subscriptions, timers, services,
                                                                                clients, guards))
        waitables = valid(waitables, lambda w: w)
        n = NumberOfEntities(len(subscriptions), len(guards), len(timers), len(clients), len(services))
        for waitable in waitables:
            n += waitable.get_num_entities()
        context = executor.context.handle
        context.__enter__()
        entered.append(context)
        wait_set = _rclpy.WaitSet(n.num_subscriptions, n.num_guard_conditions, n.num_timers, n.num_clients,
                                  n.num_services, n.num_events, context)
        for s in subscriptions:
            wait_set.add_subscription(s.handle)
        for t in timers:
            wait_set.add_timer(t.handle)
        for s in services:
            wait_set.add_service(s.handle)
        for c in clients:
            wait_set.add_client(c.handle)
        for g in guards:
            wait_set.add_guard_condition(g.handle)
        for waitable in waitables:
            waitable.add_to_wait_set(wait_set)
        wait_set.wait(int(timeout_sec * 1e9))
        ready = set(wait_set.get_ready_entities("subscription"))
        triggered = set(wait_set.get_ready_entities("guard_condition"))
        expired = set(wait_set.get_ready_entities("timer"))
        # tasks in progress (an action's execute coroutine) are polled by each turn of the executor
        turn = bool(triggered or wait_set.get_ready_entities("service") or wait_set.get_ready_entities("client")
                    or any(w.is_ready(wait_set) for w in waitables) or getattr(executor, "_tasks", None))
        for g in guards:
            if g.handle.pointer in triggered:
                g.trigger()         # (this wait took the trigger: the executor's turn must see it)
        for t in timers:
            if t.handle.pointer in expired and t.handle.is_timer_ready():   # (rcl: a cancelled timer may be in it)
                if inspect.iscoroutinefunction(t.callback) or not t.callback_group.beginning_execution(t):
                    turn = True     # (a coroutine, or a group that cannot run it now: the executor's way)
                    continue
                try:
                    t.handle.call_timer()
                    t.callback()
                finally:
                    t.callback_group.ending_execution(t)
        for s in subscriptions:
            if s.handle.pointer in ready:
                if getattr(s, "_callback_type", None) is not Subscription.CallbackType.MessageOnly:
                    turn = True     # (a callback that takes the message info: the executor's way)
                    continue
                taken = s.handle.take_message(s.msg_type, s.raw)
                if taken is not None:
                    s.callback(taken[0])
    finally:
        for h in reversed(entered):
            h.__exit__(None, None, None)
    if turn:
        _run_ready(executor)


@contextlib.contextmanager
def stop_on_signals(stop: threading.Event) -> Iterator[threading.Event]:
    """While inside, SIGINT and SIGTERM set ``stop`` (main thread only; elsewhere a no-op).

    A KeyboardInterrupt would be raised in whatever Python code runs when the signal is handled,
    often a node callback, where an executor may swallow it; a flag checked by :func:`spin` is not lost.
    """
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def run_node(node_class, args: list[str] | None = None) -> None:
    """The ``main(args=None)`` of a node module: one node on an EventsExecutor until SIGINT/SIGTERM.

    ``args`` are the process arguments (``--ros-args -r __node:=... -p ...`` are applied to the node).
    The signals stop the loop rather than shutting the context down first, so ``destroy_node``
    still runs with a valid context (it may publish and log). A signal that comes while the node is
    still being built (a launch stopped during start-up) ends the process cleanly once it is built.
    """
    with stop_on_signals(threading.Event()) as stop:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        node = None
        try:
            node = node_class()
            executor = EventsExecutor()
            executor.add_node(node)
            spin(executor, stop)
        except ExternalShutdownException:
            pass
        finally:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()

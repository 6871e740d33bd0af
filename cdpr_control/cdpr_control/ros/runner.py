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
import signal
import threading
from typing import Iterator

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, ShutdownException, TimeoutException
from rclpy.experimental import EventsExecutor
from rclpy.signals import SignalHandlerOptions

from cdpr_control.ros.intraprocess import IntraProcess

SPIN_PERIOD = 0.1  # s: longest time between checks of the stop flag


def spin(executor, stop: threading.Event | None = None) -> None:
    """Run callbacks until ``stop`` is set or the executor's context shuts down; in-process
    deliveries left over by a chain that ran out of its time budget continue between events."""
    context = executor.context
    registry = IntraProcess.of(context)
    registry.owner = threading.get_ident()  # in-process deliveries from other threads wake this one
    registry.pumped = True                  # a long in-process chain continues between events here
    try:
        while context.ok() and not (stop is not None and stop.is_set()):
            try:
                pending = registry.pending()
                if pending and isinstance(executor, Executor):
                    _run_ready(executor)
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

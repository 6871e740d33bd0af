"""Running a node's cycle once per control period on matching inputs.

In lockstep simulation every message of period k carries the stamp t_k (each node copies the
stamp of its inputs), so a node computes period k exactly once, when all its inputs for t_k are
there: the graph is a deterministic data flow. With ``mode="latest"`` (free-running, hardware) the
cycle runs on every message of the primary input with the newest of the others; ``optional``
inputs need not have arrived there (their entry is then missing), in lockstep every input is awaited.
"""
from __future__ import annotations

from typing import Callable

from .qos import CONTROL


def stamp_ns(msg) -> int:
    s = msg._header._stamp      # the slots (this runs for every message of the loop)
    return s._sec * 1_000_000_000 + s._nanosec


class StampSync:
    def __init__(self, node, inputs: dict[str, tuple[type, str]], primary: str,
                 callback: Callable[[dict, int], None], mode: str = "exact", qos=CONTROL,
                 optional: tuple[str, ...] = ()):
        if primary not in inputs:
            raise ValueError(f"primary input {primary!r} not among {list(inputs)}")
        if primary in optional or not set(optional) <= set(inputs):
            raise ValueError(f"optional inputs {optional} must be non-primary inputs among {list(inputs)}")
        self.mode = mode
        self.primary = primary
        self.callback = callback
        self.latest: dict[str, object] = {}
        self.pending: dict[int, dict[str, object]] = {}
        self.subscriptions = [
            node.create_subscription(msg_type, topic, self._receiver(name), qos)
            for name, (msg_type, topic) in inputs.items()
        ]
        self.names = tuple(inputs)
        self.required = tuple(n for n in inputs if n not in optional)

    def _receiver(self, name: str):
        def receive(msg):
            self.latest[name] = msg
            if self.mode == "latest":
                if name == self.primary and all(n in self.latest for n in self.required):
                    self.callback(dict(self.latest), stamp_ns(msg))
                return
            t = stamp_ns(msg)
            bucket = self.pending.setdefault(t, {})
            bucket[name] = msg
            if len(bucket) == len(self.names):
                # complete: run this period and forget it and anything older
                for old in [s for s in self.pending if s <= t]:
                    del self.pending[old]
                self.callback(bucket, t)
            elif len(self.pending) > 100:           # an input stopped: drop the oldest period
                del self.pending[min(self.pending)]
        return receive

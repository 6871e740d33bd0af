"""One remembered result: "compute again only when these inputs change".

The per-period code derives values from inputs that often repeat from one period to the next (a
held set-point, a pause or dwell of a program, the robot's force limits): :class:`Memo` keeps the
last result and returns it while the key of its inputs is the same. The key is built by the caller
from the inputs' exact values (bytes of the floats: a tuple of floats would take -0.0 for 0.0), so
a hit returns what the computation would return. A key of ``None`` means "not keyable" and always
computes. The kept value is shared with the caller on every hit: callers only read it, and with
``read_only`` its arrays are marked so (not where they go to a compiled kernel, which takes
writeable arrays only: :func:`cdpr_control.kernels.vector` would copy them each period).

docs/performance.md ("Memos") lists the memos and what each saves, measured by
``scripts/memo_costs.py``; a memo that saves under ~2 us a period is not worth its key.
"""
from __future__ import annotations

import numpy as np

_UNSET = object()


class Memo:
    """The last ``compute(*args)`` and its key."""

    __slots__ = ("key", "value", "read_only")

    def __init__(self, read_only: bool = False):
        self.key = _UNSET
        self.value = None
        self.read_only = read_only

    def __call__(self, key, compute, *args):
        """compute(*args), or the value of the last call while ``key`` equals its key."""
        if key is None or key != self.key:
            value = compute(*args)
            if self.read_only:
                _freeze(value)
            self.key, self.value = key, value
        return self.value

    def clear(self) -> None:
        """Forget the value: the next call computes."""
        self.key, self.value = _UNSET, None


def _freeze(value) -> None:
    if isinstance(value, np.ndarray):
        value.flags.writeable = False
    elif isinstance(value, tuple):
        for v in value:
            _freeze(v)

"""The lockstep simulator's watchdog, shared by ``winch_platform_sim`` and the graph benchmark's
skeleton simulator (benchmarks/skeleton.py), which must not import the simulator (pybullet) in
each of its processes."""
from __future__ import annotations

import time

from cdpr_control.ros.intraprocess import IntraProcess

HANDSHAKE_PERIOD = 0.5     # s, repeat of the t = 0 state until the first command


def lockstep_watchdog(node) -> None:
    """One tick of a lockstep simulator node's wall-clock watchdog: until the first command, the
    t = 0 state again every HANDSHAKE_PERIOD (late subscribers start the loop); after it, a step
    with the last command when none came within ``lockstep_timeout`` (a missed deadline).

    ``node`` has ``got_command``, ``_last_handshake``, ``lockstep_timeout``, ``_waiting_since``,
    ``missed_deadlines``, ``_publish()`` and ``_advance()``."""
    if IntraProcess.of(node.context).pending():
        # the graph in this process is still computing the period (slow, not stopped; e.g. the
        # process was descheduled on a loaded machine): neither repeat nor advance, or the run
        # would depend on the machine's load
        return
    now = time.monotonic()
    if not node.got_command:
        if now - node._last_handshake >= HANDSHAKE_PERIOD:
            node._last_handshake = now
            node._publish()
    elif node.lockstep_timeout > 0.0 and now - node._waiting_since > node.lockstep_timeout:
        node.missed_deadlines += 1
        node._advance()

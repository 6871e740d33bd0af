"""Aligned numpy series of the identification topics from a bag (header stamps = sim time)."""
from __future__ import annotations

import weakref
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdpr_tools.identify.experiments import (TOPIC_COMMAND, TOPIC_FORCES, TOPIC_MODE, TOPIC_POSE, TOPIC_SETPOINT,
    TOPIC_STATE)

_POSE_FIELDS = tuple(f"pose.position.{a}" for a in "xyz") + tuple(f"pose.orientation.{a}" for a in "xyzw")


@dataclass
class WinchSeries:
    """Samples k at the stamps t (N,) shared by every topic read: theta, thetadot, F_s (N, m)."""

    t: np.ndarray
    theta: np.ndarray
    thetadot: np.ndarray
    F_s: np.ndarray


def at_stamps(t_ref, t, values, topic):
    """Rows of values whose stamps equal t_ref (stamps in whole ns, so the match is exact)."""
    ns_ref, ns = np.rint(t_ref * 1e9).astype(np.int64), np.rint(t * 1e9).astype(np.int64)
    idx = np.searchsorted(ns, ns_ref)
    idx = np.minimum(idx, len(ns) - 1)
    if not np.array_equal(ns[idx], ns_ref):
        raise ValueError(f"{topic}: stamps do not match {TOPIC_STATE} (record them in one run)")
    return values[idx]


_SERIES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()   # bag -> {(topic, fields): series}


def _series(bag, topic: str, *fields: str) -> tuple[np.ndarray, ...]:
    """``bag.series(topic, *fields, stamp="header")``, read once per bag (reading is the slow part)."""
    cache = _SERIES.setdefault(bag, {})
    if (topic, fields) not in cache:
        cache[topic, fields] = bag.series(topic, *fields, stamp="header")
    return cache[topic, fields]


def winch_state(bag, aligned: bool = True) -> WinchSeries:
    """The winch state; ``aligned``: only the samples within the stamps of the reference forces and the
    poses (those in the bag). A recorder subscribes to each topic at its own moment and stops
    anywhere, so a bag of the graph starts and ends its topics a few periods apart."""
    t, theta, thetadot, F_s = _series(bag, TOPIC_STATE, "position", "velocity", "effort")
    if aligned:
        spans = [_series(bag, TOPIC_FORCES, "f")[0]] if TOPIC_FORCES in bag.topics else []
        spans.append(_series(bag, _pose_topic(bag), *_POSE_FIELDS)[0])
        inside = (t >= max(s[0] for s in spans)) & (t <= min(s[-1] for s in spans))
        if not inside.any():
            raise ValueError(f"{TOPIC_STATE} and the poses and forces of the bag do not overlap in time")
        t, theta, thetadot, F_s = t[inside], theta[inside], thetadot[inside], F_s[inside]
    return WinchSeries(t, theta, thetadot, F_s)


def reference_forces(bag, t) -> np.ndarray:
    """The reference force at the platform (N, m) at stamps t (ground_truth/cable_forces)."""
    t_f, f = _series(bag, TOPIC_FORCES, "f")
    return at_stamps(t, t_f, f, TOPIC_FORCES)


def _pose_topic(bag) -> str:
    return TOPIC_POSE if TOPIC_POSE in bag.topics else TOPIC_SETPOINT


def poses(bag, t) -> np.ndarray:
    """Platform poses x (N, 6) at stamps t: ground_truth/pose, else the set-point x_d."""
    from cdpr_control.ros.conversions import quaternion_to_kardan

    topic = _pose_topic(bag)
    t_p, *cols = _series(bag, topic, *_POSE_FIELDS)
    if topic == TOPIC_SETPOINT:                    # x_d of period k holds until the next one
        idx = np.clip(np.searchsorted(np.rint(t_p * 1e9), np.rint(t * 1e9), side="right") - 1, 0, None)
        cols, t_p = [c[idx] for c in cols], t
    x = np.empty((len(t_p), 6))
    x[:, :3] = np.column_stack(cols[:3])
    x[:, 3:] = [quaternion_to_kardan(*q) for q in zip(*cols[3:])]
    return at_stamps(t, t_p, x, topic)


def commands(bag) -> tuple[np.ndarray, np.ndarray]:
    """(t (K,), theta_d (K, m)) of winch/command."""
    return _series(bag, TOPIC_COMMAND, "position")


def controller(bag) -> str:
    """The joint command's mode(s) in the bag (``/joint_command/mode``: force_control, ik_only), in
    the order recorded; "controller not recorded" without that topic."""
    if TOPIC_MODE not in bag.topics:
        return "controller not recorded"
    modes = []
    for message in bag.messages([TOPIC_MODE]):
        if message.msg.data not in modes:
            modes.append(message.msg.data)
    return " then ".join(modes) or "controller not recorded"


def run_title(bag, robot) -> str:
    """What a figure of this bag names: robot, controller and bag, e.g.
    ``IPAnema 3 Mini, force_control, bag friction``."""
    return f"{robot.name}, {controller(bag)}, bag {Path(bag.path).name}"

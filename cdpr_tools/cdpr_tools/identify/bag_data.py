"""Aligned numpy series of the identification topics from a bag (header stamps = sim time)."""
from __future__ import annotations

import warnings
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
    """The winch state; ``aligned``: only the samples whose stamps the reference forces and the
    ground-truth poses of the bag have too (within the span of the set-points when the bag holds
    those instead). A recorder subscribes to each topic at its own moment and stops anywhere, so a
    bag of the graph starts and ends its topics a few periods apart; a recorder in a process of its
    own on a busy machine also loses a message now and then (a reliable keep-last publisher drops
    what a reader has not taken in time). Such samples are left out with a warning that counts them."""
    t, theta, thetadot, F_s = _series(bag, TOPIC_STATE, "position", "velocity", "effort")
    ns = np.rint(t * 1e9).astype(np.int64)
    if np.any(np.diff(ns) <= 0):
        raise ValueError(f"the stamps of {TOPIC_STATE} go back in time: two graphs published in the recorded "
                         "ROS domain (record in a ROS_DOMAIN_ID of your own)")
    if aligned:
        others = [TOPIC_FORCES] if TOPIC_FORCES in bag.topics else []
        pose_topic = _pose_topic(bag)
        if pose_topic == TOPIC_POSE:
            others.append(pose_topic)
        inside = np.ones(len(t), dtype=bool)
        for topic in others:
            inside &= np.isin(ns, np.rint(_stamps(bag, topic) * 1e9).astype(np.int64))
        if pose_topic != TOPIC_POSE:                   # x_d holds between its stamps: its span only
            t_p = _stamps(bag, pose_topic)
            inside &= (t >= t_p[0]) & (t <= t_p[-1])
        if not inside.any():
            raise ValueError(f"{TOPIC_STATE} and the poses and forces of the bag do not overlap in time")
        first, last = np.flatnonzero(inside)[[0, -1]]
        lost = int(np.count_nonzero(~inside[first:last + 1]))
        if lost:
            warnings.warn(f"{lost} of {last - first + 1} samples of {TOPIC_STATE} have no sample of "
                          f"{' or '.join(others)} with their stamp (the recorder lost them): left out", stacklevel=2)
        t, theta, thetadot, F_s = t[inside], theta[inside], thetadot[inside], F_s[inside]
    return WinchSeries(t, theta, thetadot, F_s)


def _stamps(bag, topic: str) -> np.ndarray:
    """The header stamps [s] of ``topic`` (read with the fields the loaders read, so once per bag)."""
    return _series(bag, topic, *(("f",) if topic == TOPIC_FORCES else _POSE_FIELDS))[0]


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

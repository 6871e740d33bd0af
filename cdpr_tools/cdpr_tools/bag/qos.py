"""QoS profiles as rosbag2 (metadata version 9, ROS 2 Jazzy) stores them.

Each topic carries the QoS profiles its publishers offered while recording, as a YAML list of
mappings with policy names (``reliable``, ``transient_local`` ...) and durations as ``{sec, nsec}``;
the MCAP channel metadata key ``offered_qos_profiles`` holds that list as YAML text, metadata.yaml
holds it as a list. Older bags (version 8 and below) use the policy numbers; both are read.
"""
from __future__ import annotations

import yaml
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

_POLICIES = {"history": HistoryPolicy, "reliability": ReliabilityPolicy,
             "durability": DurabilityPolicy, "liveliness": LivelinessPolicy}
_DURATIONS = ("deadline", "lifespan", "liveliness_lease_duration")
# rosbag2 plays back with its default history (keep last 10) whatever was recorded
PLAYBACK_DEPTH = 10


def qos_to_dict(qos: QoSProfile) -> dict:
    """One profile in rosbag2's version-9 layout (keys in rosbag2's order)."""
    def duration(d: Duration) -> dict:
        sec, nsec = divmod(d.nanoseconds, 1_000_000_000)
        return {"sec": sec, "nsec": nsec}

    return {
        "history": qos.history.short_key,
        "depth": qos.depth,
        "reliability": qos.reliability.short_key,
        "durability": qos.durability.short_key,
        "deadline": duration(qos.deadline),
        "lifespan": duration(qos.lifespan),
        "liveliness": qos.liveliness.short_key,
        "liveliness_lease_duration": duration(qos.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": bool(qos.avoid_ros_namespace_conventions),
    }


def qos_from_dict(d: dict) -> QoSProfile:
    """A profile from rosbag2's layout, version 9 (names) or older (numbers)."""
    def policy(key):
        enum, value = _POLICIES[key], d.get(key, 0)
        if isinstance(value, int):
            return enum(value)
        return next(m for m in enum if m.short_key == str(value).lower())

    def duration(key):
        value = d.get(key) or {}
        return Duration(nanoseconds=int(value.get("sec", 0)) * 1_000_000_000 + int(value.get("nsec", 0)))

    return QoSProfile(
        history=policy("history"), depth=int(d.get("depth", 0)), reliability=policy("reliability"),
        durability=policy("durability"), liveliness=policy("liveliness"),
        **{key: duration(key) for key in _DURATIONS},
        avoid_ros_namespace_conventions=bool(d.get("avoid_ros_namespace_conventions", False)),
    )


def dump_profiles(profiles: list[dict]) -> str:
    """The ``offered_qos_profiles`` channel metadata text (YAML block list, as yaml-cpp writes it)."""
    return yaml.safe_dump(profiles, sort_keys=False, default_flow_style=False).strip() if profiles else ""


def parse_profiles(value: str | list | None) -> list[dict]:
    """Profiles from channel metadata text or a metadata.yaml list (empty when absent)."""
    if not value:
        return []
    profiles = yaml.safe_load(value) if isinstance(value, str) else value
    return list(profiles or [])


def playback_qos(profiles: list[dict]) -> QoSProfile:
    """What to offer when playing a topic back: rosbag2's ``adapt_offer_to_recorded_offers``.

    All recorded publishers agreeing on the policies that decide compatibility -> their profile
    with the default history; disagreeing or unknown -> the default profile (reliable, volatile).
    """
    if not profiles:
        return QoSProfile(depth=PLAYBACK_DEPTH)
    first = qos_from_dict(profiles[0])
    key = _compatibility_key(first)
    if any(_compatibility_key(qos_from_dict(p)) != key for p in profiles[1:]):
        return QoSProfile(depth=PLAYBACK_DEPTH)
    first.history, first.depth = HistoryPolicy.KEEP_LAST, PLAYBACK_DEPTH
    return first


def _compatibility_key(q: QoSProfile) -> tuple:
    return (q.reliability, q.durability, q.deadline.nanoseconds, q.liveliness,
            q.liveliness_lease_duration.nanoseconds)

"""Exclusive locks on files (``fcntl.flock``): one process at a time (starting the CLI daemon,
identifying a plant's friction for the validation sweep), and one test session or benchmark per ROS
domain on this machine."""
from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
from pathlib import Path
from typing import IO, Iterator


@contextlib.contextmanager
def locked(lock_path: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``lock_path`` (created if missing) inside the block."""
    with open(lock_path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def claim_ros_domain(first: int) -> tuple[int, IO]:
    """The first ROS domain from ``first`` on (cycling through 1..100) that no other test session or
    benchmark on this machine holds, and its lock (an flock on a file in the temporary directory,
    held until the file is closed or the process ends). Random domains alone collided: with several
    sessions on one machine, a graph received another's /winch/state and /ground_truth/pose."""
    for k in range(100):
        domain = 1 + (first - 1 + k) % 100
        lock = open(Path(tempfile.gettempdir()) / f"cdpr-test-ros-domain-{domain}.lock", "w")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.close()
            continue
        return domain, lock
    raise RuntimeError("every ROS domain 1..100 is held by another test session on this machine")


def own_ros_domain(first: int) -> IO | None:
    """Set ROS_DOMAIN_ID to a domain of this process's own (:func:`claim_ros_domain`) unless the
    caller chose one; returns the lock to keep for the process's life (None when the caller chose)."""
    if os.environ.get("ROS_DOMAIN_ID"):
        return None
    domain, lock = claim_ros_domain(first)
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    return lock

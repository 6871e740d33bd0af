"""Geometric path segments of a G-code program (thesis section 2.3.2: geometric path planning).

A segment is a curve q(s) in the 9-D path vector q = [x y z a b c u v w] (pose with Kardan angles
and the force axes F_d,0 of section 5.1.2), parametrised by a path parameter s in [0, length].
The position part is a straight line or a circular arc (optionally a helix); angles and forces
are interpolated linearly in s, so they change "with the motion" as in section 5.1.2.

s is the length travelled in the segment's metric: the position path length when the position
moves, otherwise the rotation angle, otherwise the force change. Arcs therefore stay exactly on
the arc whatever the time law s(t) is.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

#: Slices of a 9-D path vector q = [x y z a b c u v w].
POSITION = slice(0, 3)
ROTATION = slice(3, 6)
FORCE = slice(6, 9)
GROUPS = (POSITION, ROTATION, FORCE)
METRIC_NAMES = ("position", "rotation", "force")

#: Travel below this (m, rad or N) is no motion: such moves are dropped by the parser.
MIN_TRAVEL = 1e-9


def travel_metric(delta: np.ndarray) -> int | None:
    """Index into GROUPS of the group that defines s for a change delta (9,), or None if none moves."""
    for index, group in enumerate(GROUPS):
        if np.linalg.norm(delta[group]) > MIN_TRAVEL:
            return index
    return None


def _group_norms(v: np.ndarray) -> np.ndarray:
    return np.array([np.linalg.norm(v[g]) for g in GROUPS])


class Segment:
    """Base of the path segments: q0, q1 (9,), length L, metric, and q(s) with derivatives."""

    q0: np.ndarray
    q1: np.ndarray
    length: float
    metric: int

    def at(self, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q(s), dq/ds, d2q/ds2 for s in [0, length] (clamped)."""
        raise NotImplementedError

    def bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Upper bounds (3,) per group (position, rotation, force) of |dq/ds|, |d2q/ds2|, |d3q/ds3|."""
        raise NotImplementedError


class LineSegment(Segment):
    """q(s) = q0 + (q1 - q0) s / L: G0/G1, and pure rotation or pure force moves."""

    def __init__(self, q0: np.ndarray, q1: np.ndarray, metric: int):
        self.q0 = np.array(q0, dtype=float)
        self.q1 = np.array(q1, dtype=float)
        self.metric = metric
        delta = self.q1 - self.q0
        self.length = float(np.linalg.norm(delta[GROUPS[metric]]))
        self._dq = delta / self.length
        self._zero = np.zeros(9)

    def at(self, s):
        if s >= self.length:
            return self.q1.copy(), self._dq.copy(), self._zero.copy()
        return self.q0 + self._dq * max(s, 0.0), self._dq.copy(), self._zero.copy()

    def bounds(self):
        return _group_norms(self._dq), np.zeros(3), np.zeros(3)


class ArcSegment(Segment):
    """G2/G3: circular arc (helix if the plane-normal coordinate changes) in the position part.

    p(s) = c + r(s) (cos th e1 + sin th e2) + n h s/L with th = th0 + sweep s/L and
    r = r0 + (r1 - r0) s/L. r1 differs from r0 only by the tolerated rounding of the programmed
    end point, so the end point is met exactly. e1, e2, n is the right-handed plane basis
    (G17: x y z, G18: z x y, G19: y z x); sweep > 0 is counter-clockwise seen from +n (G3).
    """

    def __init__(self, q0, q1, centre, e1, e2, n, r0, r1, theta0, sweep, height):
        self.q0 = np.array(q0, dtype=float)
        self.q1 = np.array(q1, dtype=float)
        self.metric = 0
        self.centre = np.asarray(centre, dtype=float)
        self.e1, self.e2, self.n = (np.asarray(v, dtype=float) for v in (e1, e2, n))
        self.r0, self.r1 = float(r0), float(r1)
        self.theta0, self.sweep, self.height = float(theta0), float(sweep), float(height)
        self.length = math.hypot(0.5 * (self.r0 + self.r1) * self.sweep, self.height)
        self._dth = self.sweep / self.length
        self._dr = (self.r1 - self.r0) / self.length
        self._dh = self.height / self.length
        delta = self.q1 - self.q0
        self._dlin = np.concatenate([np.zeros(3), delta[3:] / self.length])
        self._basis = np.stack([self.e1, self.e2, self.n])

    def at(self, s):
        s = min(max(s, 0.0), self.length)
        th = self.theta0 + self._dth * s
        r = self.r0 + self._dr * s
        c, sn = math.cos(th), math.sin(th)
        dth, dr = self._dth, self._dr
        # rows: p - centre, p', p'' in the plane basis (e1, e2, n); one product maps them to xyz
        coeffs = np.array([[r * c, r * sn, self._dh * s],
                           [dr * c - r * dth * sn, dr * sn + r * dth * c, self._dh],
                           [-2.0 * dr * dth * sn - r * dth**2 * c, 2.0 * dr * dth * c - r * dth**2 * sn, 0.0]])
        rows = coeffs @ self._basis
        q = self.q0 + self._dlin * s
        q[POSITION] = self.q1[POSITION] if s == self.length else self.centre + rows[0]
        dq = self._dlin.copy()
        dq[POSITION] = rows[1]
        ddq = np.zeros(9)
        ddq[POSITION] = rows[2]
        return q, dq, ddq

    def bounds(self):
        r_max = max(self.r0, self.r1)
        dth, dr = abs(self._dth), abs(self._dr)
        d1 = _group_norms(self._dlin)
        d1[0] = math.sqrt(dr**2 + (r_max * dth) ** 2 + self._dh**2)
        d2 = np.array([2.0 * dr * dth + r_max * dth**2, 0.0, 0.0])
        d3 = np.array([3.0 * dr * dth**2 + r_max * dth**3, 0.0, 0.0])
        return d1, d2, d3


def joins_smoothly(a: Segment, b: Segment) -> bool:
    """True if b continues a with equal dq/ds and d2q/ds2, so the path can be passed at speed.

    Then velocity and acceleration x' s', x'' s'^2 + x' s'' stay continuous across the joint;
    any other joint (a corner, a line into an arc) needs a stop to keep the geometry exact."""
    if a.metric != b.metric:
        return False
    _, da, dda = a.at(a.length)
    _, db, ddb = b.at(0.0)
    same_tangent = np.max(np.abs(da - db)) <= 1e-9 * (1.0 + np.max(np.abs(da)))
    same_curvature = np.max(np.abs(dda - ddb)) <= 1e-9 * (1.0 + np.max(np.abs(dda)))
    return bool(same_tangent and same_curvature)


class Chain:
    """Segments joined smoothly (joins_smoothly) and travelled as one path with s in [0, length]."""

    def __init__(self, segments: list[Segment]):
        self.segments = list(segments)
        self.offsets = [0.0]
        for seg in self.segments:
            self.offsets.append(self.offsets[-1] + seg.length)
        self.length = self.offsets[-1]
        self.start = self.segments[0].q0
        self.end = self.segments[-1].q1
        self.metric = self.segments[0].metric

    def locate(self, s: float) -> int:
        """Index of the segment holding chain parameter s."""
        return min(max(bisect.bisect_right(self.offsets, s) - 1, 0), len(self.segments) - 1)

    def at(self, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q(s), dq/ds, d2q/ds2 along the chain."""
        i = self.locate(s)
        return self.segments[i].at(s - self.offsets[i])

    def bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Group-wise maxima of the segments' derivative bounds."""
        all_bounds = [seg.bounds() for seg in self.segments]
        return tuple(np.max([b[k] for b in all_bounds], axis=0) for k in range(3))

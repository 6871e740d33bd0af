"""Virtual workspace zones of the admittance control, thesis section 5.2.1, Fig. 5.11 and Fig. 5.12.

A zone set is a small declarative description: an ordered list of zones around the origin x_0,
each a shape with its own virtual parameters c, d, m (per axis, [x y z a b c]) and a spring:

    Zone("rest", "sphere", 0.01,  c=..., d=..., m=..., spring="origin")   # zone 1: pulled to x_0
    Zone("free", "box", half,     c=0,   d=..., m=..., spring="origin")   # zone 2: damped, no spring
    Zone("wall", "outside", None, c=..., d=..., m=..., spring="border")   # zone 3: virtual wall

The zone of a pose is the first that contains it: a sphere by the distance of the platform's
midpoint from r_0 (the thesis' zone 1), a box by all six coordinates x - x_0 within its half-widths
[m, m, m, rad, rad, rad], "outside" contains every pose and must come last. The spring of a zone is

    origin:  w_spring = -c (x - x_0)                      (5.5) about the rest pose
    border:  w_spring = -c (x - clip(x, box))             normal to the faces of the last box

so zone 3's force grows from zero at the border (continuous), while zone 1's spring drops from
c R_1 to zero when the platform leaves the sphere: the thesis' "dragging two magnets apart"
(section 5.2.3). That switch is deliberate and documented, not smoothed (docs/admittance.md).

The wall zone never leaves the wrench-feasible workspace (WFW, section 2.2.1) when the *hard box*,
the last box widened by the largest penetration a bounded user wrench and velocity can cause,
lies in the WFW: :func:`max_penetration`, :func:`hard_box`, :func:`check_in_workspace`. Near the
border of the WFW a configured zone set may not fit: :func:`fit_in_workspace` then shrinks the free
box and the rest sphere by one factor until the hard box fits, and says so (:class:`Clipping`). This
departs from the thesis, which guided the Mini about one pose only (docs/admittance.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SHAPES = ("sphere", "box", "outside")
SPRINGS = ("origin", "border")


def per_axis(value, name: str, minimum: float = 0.0, strict: bool = False) -> np.ndarray:
    """Six values per axis [x y z a b c] from a scalar (all axes), [translational, rotational] or
    six values; each >= minimum (> minimum with ``strict``)."""
    v = np.atleast_1d(np.asarray(value, dtype=float))
    if v.shape == (1,):
        v = np.full(6, v[0])
    elif v.shape == (2,):
        v = np.repeat(v, 3)
    if v.shape != (6,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} needs 1, 2 or 6 finite values, got {value!r}")
    if np.any(v <= minimum) if strict else np.any(v < minimum):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {minimum:g} on every axis, got {v.tolist()}")
    return v


@dataclass(frozen=True)
class Zone:
    """One zone: shape, size, virtual stiffness c [N/m, N m/rad], damping d [N s/m, N m s/rad],
    mass m [kg, kg m^2] per axis, and what its spring pulls towards."""

    name: str
    shape: str
    size: object = None          # sphere: radius [m]; box: half-widths (1, 2 or 6 values); outside: None
    c: object = 0.0
    d: object = 1.0
    m: object = 1.0
    spring: str = "origin"

    def __post_init__(self):
        if self.shape not in SHAPES:
            raise ValueError(f"zone {self.name!r}: shape must be one of {SHAPES}, got {self.shape!r}")
        if self.spring not in SPRINGS:
            raise ValueError(f"zone {self.name!r}: spring must be one of {SPRINGS}, got {self.spring!r}")
        object.__setattr__(self, "c", per_axis(self.c, f"zone {self.name!r} c"))
        object.__setattr__(self, "d", per_axis(self.d, f"zone {self.name!r} d"))
        object.__setattr__(self, "m", per_axis(self.m, f"zone {self.name!r} m", strict=True))
        if self.shape == "sphere":
            radius = float(np.asarray(self.size, dtype=float))
            if not (np.isfinite(radius) and radius > 0.0):
                raise ValueError(f"zone {self.name!r}: sphere radius must be > 0 m, got {self.size!r}")
            object.__setattr__(self, "size", radius)
        elif self.shape == "box":
            object.__setattr__(self, "size", per_axis(self.size, f"zone {self.name!r} box half-widths", strict=True))
        elif self.size is not None:
            raise ValueError(f"zone {self.name!r}: an outside zone has no size")

    def contains(self, e: np.ndarray) -> bool:
        """Whether the pose with x - x_0 = e lies in this zone's shape."""
        if self.shape == "sphere":
            return float(np.linalg.norm(e[:3])) <= self.size
        if self.shape == "box":
            return bool(np.all(np.abs(e) <= self.size))
        return True


@dataclass(frozen=True)
class ZoneSet:
    """Ordered zones around the origin x_0; the last is the "outside" wall of the last box."""

    zones: tuple
    x_0: np.ndarray = field(default_factory=lambda: np.zeros(6))

    def __post_init__(self):
        zones = tuple(self.zones)
        object.__setattr__(self, "zones", zones)
        object.__setattr__(self, "x_0", _finite6(self.x_0, "zone origin x_0"))
        if not zones or zones[-1].shape != "outside":
            raise ValueError("the last zone must be 'outside' (every pose needs a zone)")
        if any(z.shape == "outside" for z in zones[:-1]):
            raise ValueError("only the last zone may be 'outside'")
        if zones[-1].spring == "border" and self.box is None:
            raise ValueError("a 'border' spring needs a box zone before it")
        if any(z.spring == "border" and z.shape != "outside" for z in zones):
            raise ValueError("only the outside zone may have a 'border' spring")
        names = [z.name for z in zones]
        if len(set(names)) != len(names):
            raise ValueError(f"zone names must be unique, got {names}")

    @property
    def box(self) -> np.ndarray | None:
        """Half-widths of the last box zone: the border of the virtual workspace."""
        boxes = [z.size for z in self.zones if z.shape == "box"]
        return boxes[-1] if boxes else None

    def index(self, x) -> int:
        """Index of the zone of pose x (0 = first)."""
        e = np.asarray(x, dtype=float) - self.x_0
        return next(i for i, z in enumerate(self.zones) if z.contains(e))

    def spring(self, i: int, x) -> tuple[np.ndarray, np.ndarray]:
        """(c_eff, x_t) per axis in zone i at pose x: the spring force is -c_eff (x - x_t).

        For a border spring, only the axes outside the box are sprung, towards the face."""
        zone = self.zones[i]
        x = np.asarray(x, dtype=float)
        if zone.spring == "origin":
            return zone.c, self.x_0.copy()
        lo, hi = self.x_0 - self.box, self.x_0 + self.box
        target = np.clip(x, lo, hi)
        return np.where(target != x, zone.c, 0.0), target


def _finite6(value, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    if v.shape != (6,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} needs 6 finite values, got {value!r}")
    return v


def thesis_zones(x_0=np.zeros(6), rest_radius: float = 0.01, c_rest=(1000.0, 20.0), box=(0.03, 0.05),
                 c_free=(0.0, 20.0), c_wall=(1000.0, 50.0), d_rest=(40.0, 0.5), d=(150.0, 0.5),
                 m=(2.0, 0.01)) -> ZoneSet:
    """The three zones of section 5.2.1 (Fig. 5.12): rest sphere R_1 = 0.01 m with c = 1000 N/m
    (2.6 N hold it at 2.6 mm, 10.2 N for 0.27 s leave it), free box to the border at 0.03 m, wall
    beyond. The thesis gives no d and m: the rest zone is lightly damped so a pulse can leave it,
    the free and wall zones are damped more so the platform stops soon after a push (ASSUMPTION).
    The rotational axes keep a soft spring to the rest orientation in zones 1 and 2 (the thesis
    guides positions) and have a wall at 0.05 rad: the IPAnema 3 Mini's wrench-feasible
    orientations are small (ASSUMPTION: rotational c, d, m)."""
    return ZoneSet((Zone("rest", "sphere", rest_radius, c=c_rest, d=d_rest, m=m),
                    Zone("free", "box", box, c=c_free, d=d, m=m),
                    Zone("wall", "outside", None, c=c_wall, d=d, m=m, spring="border")), x_0)


def max_penetration(zones: ZoneSet, w_max, v_max) -> np.ndarray:
    """Upper bound of the penetration into the wall zone per axis [m, rad].

    Entering at |v| <= v_max and pushed by |w| <= w_max, the wall spring stops the axis within
    w_max / c + v_max sqrt(m / c) (static deflection plus kinetic energy m v^2 / 2 turned into
    spring energy c p^2 / 2; damping only shortens it). An axis without wall spring is unbounded.
    """
    wall = zones.zones[-1]
    w_max, v_max = per_axis(w_max, "w_max"), per_axis(v_max, "v_max")
    with np.errstate(divide="ignore"):
        return np.where(wall.c > 0.0, w_max / wall.c + v_max * np.sqrt(wall.m / np.maximum(wall.c, 1e-300)),
                        np.inf)


def hard_box(zones: ZoneSet, w_max, v_max) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) poses the virtual system is clamped to: the last box widened by
    :func:`max_penetration`. Reached only if the bounds are violated (a safeguard)."""
    if zones.box is None:
        raise ValueError("zones without a box have no hard limit")
    reach = zones.box + max_penetration(zones, w_max, v_max)
    return zones.x_0 - reach, zones.x_0 + reach


def box_samples(lower, upper) -> np.ndarray:
    """Poses on the border of a 6-D box: 3^3 translational points (corners, edge and face
    centres) times the 2^3 orientation corners, and the centre (217, 6)."""
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    grid = [np.array([lo, 0.5 * (lo + hi), hi]) for lo, hi in zip(lower[:3], upper[:3])]
    r = np.stack(np.meshgrid(*grid, indexing="ij"), axis=-1).reshape(-1, 3)
    rot = np.stack(np.meshgrid(*[[lo, hi] for lo, hi in zip(lower[3:], upper[3:])], indexing="ij"),
                   axis=-1).reshape(-1, 3)
    poses = np.hstack([np.repeat(r, len(rot), axis=0), np.tile(rot, (len(r), 1))])
    return np.vstack([0.5 * (lower + upper), poses])


def check_in_workspace(robot, zones: ZoneSet, w_max, v_max, f_min=None, f_max=None) -> None:
    """Raise ValueError unless the hard box lies in the WFW of ``robot`` (include a known payload
    in ``robot``): sampled at :func:`box_samples` with the exact QP membership test."""
    from cdpr_control.model.workspace import feasible_poses

    lower, upper = hard_box(zones, w_max, v_max)
    if not np.all(np.isfinite(lower)) or not np.all(np.isfinite(upper)):
        raise ValueError("the wall zone needs c > 0 on every axis to bound the workspace")
    poses = box_samples(lower, upper)
    ok = feasible_poses(robot, poses, "qp", f_min, f_max)
    if not np.all(ok):
        worst = poses[~ok][0]
        raise ValueError(f"the virtual workspace with its wall reach {np.round(upper - zones.x_0, 4).tolist()} "
                         f"leaves the wrench-feasible workspace, e.g. at {np.round(worst, 4).tolist()}")


def box_from_workspace(robot, x_0, shape, w_max, v_max, zones: ZoneSet, tol: float = 1e-3,
                       f_min=None, f_max=None) -> np.ndarray:
    """The largest box k * shape (half-widths) for the free zone whose hard box lies in the WFW,
    by bisection on k (to ``tol`` relative); ``zones`` gives the wall and the other zones."""
    shape = per_axis(shape, "box shape", strict=True)

    def fits(k):
        z = ZoneSet(tuple(Zone(zn.name, zn.shape, k * shape if zn.shape == "box" else zn.size,
                               zn.c, zn.d, zn.m, zn.spring) for zn in zones.zones), x_0)
        try:
            check_in_workspace(robot, z, w_max, v_max, f_min, f_max)
            return True
        except ValueError:
            return False

    lo, hi = 0.0, 1.0
    while fits(hi):
        lo, hi = hi, 2.0 * hi
        if hi > 1e3:
            raise ValueError("the workspace seems unbounded along the box shape")
    while hi - lo > tol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    if lo == 0.0:
        raise ValueError("no box of this shape fits: the origin's wall reach leaves the workspace")
    return lo * shape


@dataclass(frozen=True)
class Clipping:
    """How :func:`fit_in_workspace` shrank a zone set so that its hard box lies in the WFW: the free
    box and the rest sphere scaled by ``scale`` (< 1); where the wall's reach alone left the WFW,
    also the user wrench's saturation w_max and the velocity limit v_max by ``reach_scale`` (< 1;
    the reach is proportional to them)."""

    scale: float
    box: np.ndarray              # configured half-widths of the free box
    rest_radius: float           # configured radius of the rest sphere [m]
    reach_scale: float = 1.0

    def text(self) -> str:
        box = np.round(self.scale * self.box, 4).tolist()
        reach = (f"; v_max and w_max scaled by {self.reach_scale:.3g} too (w_max at least "
                 f"{W_MAX_OVER_DEAD_BAND:g} x the dead band)" if self.reach_scale < 1.0 else "")
        return (f"virtual workspace clipped to the wrench-feasible workspace: free box and rest sphere scaled "
                f"by {self.scale:.3g} (box half-widths {box}, rest radius {self.scale * self.rest_radius:.4g} m; "
                f"configured {np.round(self.box, 4).tolist()}, {self.rest_radius:g} m){reach}")


def scaled(zones: ZoneSet, k: float) -> ZoneSet:
    """The zone set with its box and sphere zones scaled by k about x_0 (c, d, m kept)."""
    return ZoneSet(tuple(Zone(z.name, z.shape, None if z.size is None else k * np.asarray(z.size), z.c, z.d, z.m,
                              z.spring) for z in zones.zones), zones.x_0)


def _largest(fits, lo: float, tol: float) -> float:
    """The largest k in (lo, 1) with fits(k), by bisection to ``tol`` (lo: none fits)."""
    hi = 1.0
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


def force_limits(robot, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(f_min + margin, f_max - margin) (m,) [N] of the robot's cable limits: the limits the hard box
    is fitted in (``zones.force_margin``, :func:`cdpr_control.control.admittance.fitted_settings`).

    The margin is what the cable forces may differ from a planned distribution within the limits:
    the force control's tracking error and the force sensors' error (slope and offset of (3.29)).
    Without it a platform the wall pushed back to the border of the free box rests where the
    distribution plans a cable within a fraction of a newton of f_max, and its true force lies
    beyond (the Mini's grid pose #1: set-point 39.74 N, true 40.31 N for f_max 40 N;
    docs/admittance.md). ValueError where nothing is left between them."""
    if not margin >= 0.0:
        raise ValueError(f"zones.force_margin must be >= 0 N, got {margin}")
    c = robot.cable
    f_min = np.asarray(c.f_min, dtype=float) * np.ones(robot.m) + margin
    f_max = np.asarray(c.f_max, dtype=float) * np.ones(robot.m) - margin
    if np.any(f_min >= f_max):
        raise ValueError(f"zones.force_margin {margin} N leaves no force between the cable limits")
    return f_min, f_max


W_MAX_OVER_DEAD_BAND = 1.25   # a shrunk w_max stays this far above the dead band (a user wrench of 20 % of it)


def fit_in_workspace(robot, zones: ZoneSet, w_max, v_max, dead_band=0.0, tol: float = 1e-3, f_min=None,
                     f_max=None) -> tuple[ZoneSet, np.ndarray, np.ndarray, Clipping | None]:
    """(zones, w_max, v_max, clipping) whose hard box lies in the WFW of ``robot``: as given when
    it does (clipping None); else the zones scaled by the largest k < 1 that fits (by bisection to
    ``tol``), the dynamics and limits kept; where no k does (the wall's reach
    :func:`max_penetration` alone leaves the WFW), the zones, v_max and w_max all scaled by the
    largest k that fits (the reach is proportional to v_max and w_max: near the border the user
    guides slower and with less force), w_max kept W_MAX_OVER_DEAD_BAND above the dead band.
    ValueError when nothing fits even so."""
    w_max, v_max = per_axis(w_max, "w_max"), per_axis(v_max, "v_max")
    w_floor = W_MAX_OVER_DEAD_BAND * per_axis(dead_band, "dead_band")

    def fits(k, limits_too=False):
        w, v = (np.maximum(k * w_max, np.minimum(w_floor, w_max)), k * v_max) if limits_too else (w_max, v_max)
        try:
            check_in_workspace(robot, scaled(zones, k), w, v, f_min, f_max)
            return True
        except ValueError:
            return False

    spheres = [z.size for z in zones.zones if z.shape == "sphere"]
    radius = float(spheres[0]) if spheres else 0.0
    if fits(1.0):
        return zones, w_max, v_max, None
    k = _largest(fits, 0.0, tol)
    if k > 0.0:
        return scaled(zones, k), w_max, v_max, Clipping(k, zones.box, radius)
    k = _largest(lambda k: fits(k, True), 0.0, tol)
    if k == 0.0:
        reach = np.round(max_penetration(zones, w_max, v_max), 4).tolist()
        raise ValueError(f"no virtual workspace fits at this origin: the wall's reach {reach} leaves the "
                         "wrench-feasible workspace even with w_max and v_max scaled down (w_max to "
                         f"{W_MAX_OVER_DEAD_BAND:g} x the dead band; move the zone origin inwards)")
    w = np.maximum(k * w_max, np.minimum(w_floor, w_max))
    return scaled(zones, k), w, k * v_max, Clipping(k, zones.box, radius, k)

"""Admittance control for hand guiding, thesis section 5.2: a measured wrench drives a virtual
mass-spring-damper whose pose is the desired pose x_d,Adm (Fig. 5.13).

Virtual system (5.4)-(5.8), per axis i of x = [x y z a b c] (Kardan angles, section 2.1.1):

    m_i xddot_i + d_i xdot_i + c_i (x_i - x_t,i) = w_Adm,i

with c, d, m and the spring target x_t from the zone of the current pose
(:mod:`cdpr_control.control.admittance_zones`, section 5.2.1). It is discretised *exactly* for an input
held over the period (zero-order hold): [e, v]_{k+1} = Phi [e, v]_k + Gamma w_k with
Phi = exp(A T), A = [[0, 1], [-c/m, -d/m]], so the discrete poles are exp(s T) of the continuous
ones and the eigenfrequency (5.12) has no discretisation error. Velocity and acceleration limits
and the hard box (the wrench-feasible limit of the zones) act after the exact step; while one of
them acts the step is the limited one instead (documented in docs/admittance.md).

User wrench (5.9), with the weight and the platform's inertia from the model instead of the
thesis' w_init / g estimate:

    w_Adm = DB(PT1(w - w_g(x_d) + w_dyn(x_d, xdot_d, xddot_d) - w_tare))

w the measured wrench (2.11), w_g, w_dyn the weight and inverse dynamics (2.33) of the platform
with its known payload, w_tare the remainder at switch-on (the thesis' w_init: sensor offsets and
model errors; averaged over ``tare_time``, during which the platform holds), PT1 the filter of
T_1 = 3 ms, DB a dead band per axis, then a saturation at w_max.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.linalg import expm

from cdpr_control.control.admittance_zones import (ZoneSet, fit_in_workspace, force_limits, hard_box, per_axis,
    thesis_zones)
from cdpr_control.model.dynamics import dynamic_wrench, gravity_wrench
from cdpr_control.control.filters import LowPass
from cdpr_control.model.kinematics import twist_from_pose_rates


def exact_step_matrices(c: float, d: float, m: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(Phi (2, 2), Gamma (2,)) of m xddot + d xdot + c e = w, exact for w held over dt."""
    M = np.zeros((3, 3))
    M[0, 1] = 1.0
    M[1, 0], M[1, 1], M[1, 2] = -c / m, -d / m, 1.0 / m
    E = expm(M * dt)
    return E[:2, :2], E[:2, 2]


def damped_eigenfrequency(c: float, d: float, m: float) -> float:
    """omega_d,theo of (5.12) in Hz (the thesis' table 5.3 lists it in Hz); an overdamped system
    (d >= 2 sqrt(c m)) does not oscillate: ValueError."""
    radicand = c / m - (d / (2.0 * m)) ** 2
    if not radicand > 0.0:
        raise ValueError(f"c = {c}, d = {d}, m = {m} is not underdamped: no eigenfrequency")
    return float(np.sqrt(radicand) / (2.0 * np.pi))


@dataclass
class UserWrenchParams:
    """Input of the virtual system (5.9). Pairs are [translational, rotational] or six values."""

    T_filter: float = 0.003                                    # s, PT1 of (5.9), section 5.2.2
    dead_band: object = field(default_factory=lambda: [0.5, 0.02])   # N, N m (ASSUMPTION: above the idle wrench)
    w_max: object = field(default_factory=lambda: [20.0, 0.5])       # N, N m, saturation (ASSUMPTION)
    tare_on_enable: bool = True                                # the thesis' w_init at start-up
    tare_time: float = 0.0                                     # s, w_init is the mean over this after switch-on (0: one sample)
    inertia_compensation: bool = True                          # the m_p xddot_d term of (5.9)

    def validate(self) -> None:
        if not self.T_filter >= 0.0:
            raise ValueError(f"T_filter must be >= 0 s, got {self.T_filter}")
        if not self.tare_time >= 0.0:
            raise ValueError(f"tare_time must be >= 0 s, got {self.tare_time}")
        per_axis(self.dead_band, "dead_band")
        w_max = per_axis(self.w_max, "w_max")
        if np.any(w_max <= per_axis(self.dead_band, "dead_band")):
            raise ValueError("w_max must exceed the dead band on every axis")


class UserWrench:
    """w_Adm (5.9) from the measured wrench; the robot includes the known payload."""

    def __init__(self, robot, dt: float, params: UserWrenchParams | None = None):
        self.robot = robot
        self.dt = dt
        self.filter = LowPass(0.0, dt)
        self.tare = np.zeros(6)
        self._tare_sum, self._tare_count, self._tare_left = np.zeros(6), 0, 0
        self.set_params(params or UserWrenchParams())

    def set_params(self, params: UserWrenchParams) -> None:
        params.validate()
        self.params = params
        self.dead_band = per_axis(params.dead_band, "dead_band")
        self.w_max = per_axis(params.w_max, "w_max")
        self.filter.set_time_constant(params.T_filter)

    def raw(self, w, x_d, xdot_d=None, xddot_d=None) -> np.ndarray:
        """w - w_g + w_dyn: what is left of the measured wrench for the user (before the tare).

        xdot_d, xddot_d: twist and its derivative of the set-point (base frame, as in the loop)."""
        r = np.asarray(w, dtype=float) - gravity_wrench(self.robot, x_d)
        if self.params.inertia_compensation and xdot_d is not None:
            xddot_d = np.zeros(6) if xddot_d is None else xddot_d
            r = r + dynamic_wrench(self.robot, x_d, xdot_d, xddot_d)
        return r

    def reset(self, raw) -> None:
        """Switch-on: tare the remainder (if configured) and start the filter there.

        The tare is the mean of the raw wrench over ``tare_time`` from here on (0: this sample, the
        thesis' w_init): one sample carries the full sensor noise (on the IPAnema 3 sigma 3 N m
        about z), which the dead band would then see as a lasting user wrench; the mean over
        0.1 s has a tenth of it."""
        raw = np.asarray(raw, dtype=float)
        self.tare = raw.copy() if self.params.tare_on_enable else np.zeros(6)
        self._tare_sum, self._tare_count = self.tare.copy(), 1
        self._tare_left = int(round(self.params.tare_time / self.dt)) - 1 if self.params.tare_on_enable else 0
        self.filter.reset(raw - self.tare)

    def update(self, raw) -> np.ndarray:
        """One period: filtered, dead band (continuous: |w| - band), saturated; zero while taring."""
        if self._tare_left > 0:
            self._tare_sum += np.asarray(raw, dtype=float)
            self._tare_count += 1
            self._tare_left -= 1
            self.tare = self._tare_sum / self._tare_count
            self.filter.reset(np.zeros(6))
            return np.zeros(6)
        y = self.filter.update(np.asarray(raw, dtype=float) - self.tare)
        y = np.sign(y) * np.maximum(np.abs(y) - self.dead_band, 0.0)
        return np.clip(y, -self.w_max, self.w_max)


class VirtualSystem:
    """The exactly discretised virtual system of all six axes with zones and limits."""

    def __init__(self, zones: ZoneSet, dt: float, v_max, a_max, limit_box=None):
        self.dt = dt
        self.configure(zones, v_max, a_max, limit_box)
        self.x = zones.x_0.copy()
        self.v = np.zeros(6)
        self.a = np.zeros(6)
        self.zone = zones.index(self.x)
        self.limited = np.zeros(6, dtype=bool)
        self._cache: dict[tuple, tuple] = {}

    def configure(self, zones: ZoneSet, v_max, a_max, limit_box=None) -> None:
        """Zones, limits [m/s, rad/s], [m/s^2, rad/s^2] and the hard box (lower, upper) or None."""
        self.zones = zones
        self.v_max = per_axis(v_max, "v_max", strict=True)
        self.a_max = per_axis(a_max, "a_max", strict=True)
        self.limit_box = None if limit_box is None else (np.asarray(limit_box[0], float), np.asarray(limit_box[1], float))

    def reset(self, x, v=None) -> None:
        self.x = np.array(x, dtype=float)
        self.v = np.zeros(6) if v is None else np.array(v, dtype=float)
        self.a = np.zeros(6)
        self.zone = self.zones.index(self.x)

    def _matrices(self, c, d, m) -> tuple[np.ndarray, np.ndarray]:
        """(Phi (6, 2, 2), Gamma (6, 2)) of the six axes, cached per zone parameters."""
        key = (tuple(c), tuple(d), tuple(m))
        if key not in self._cache:
            if len(self._cache) > 256:           # live parameter changes: keep the cache small
                self._cache.clear()
            pairs = [exact_step_matrices(float(ci), float(di), float(mi), self.dt) for ci, di, mi in zip(c, d, m)]
            self._cache[key] = (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))
        return self._cache[key]

    def step(self, w) -> np.ndarray:
        """Advance one period with the user wrench w (6,) held; returns x_{k+1}."""
        w = np.asarray(w, dtype=float)
        self.zone = self.zones.index(self.x)
        zone = self.zones.zones[self.zone]
        c, x_t = self.zones.spring(self.zone, self.x)
        x0, v0 = self.x, self.v
        Phi, Gamma = self._matrices(c, zone.d, zone.m)
        ev = np.einsum("aij,aj->ai", Phi, np.stack([x0 - x_t, v0], axis=1)) + Gamma * w[:, None]
        x1, v1 = x_t + ev[:, 0], ev[:, 1]
        a1 = (w - zone.d * v1 - c * ev[:, 0]) / zone.m
        # limits: where the exact step exceeds them, the limited step (trapezoidal position)
        a_mean = (v1 - v0) / self.dt
        limited = (np.abs(a_mean) > self.a_max) | (np.abs(v1) > self.v_max)
        if np.any(limited):
            v_lim = np.clip(v0 + np.clip(a_mean, -self.a_max, self.a_max) * self.dt, -self.v_max, self.v_max)
            x1 = np.where(limited, x0 + 0.5 * (v0 + v_lim) * self.dt, x1)
            a1 = np.where(limited, (v_lim - v0) / self.dt, a1)
            v1 = np.where(limited, v_lim, v1)
        if self.limit_box is not None:                       # last resort: never leave the hard box
            lo, hi = self.limit_box
            clamped = (x1 < lo) | (x1 > hi)
            if np.any(clamped):
                x1 = np.clip(x1, lo, hi)
                v1 = np.where(clamped, 0.0, v1)
                a1 = np.where(clamped, 0.0, a1)
                limited |= clamped
        self.limited = limited
        self.x, self.v, self.a = x1, v1, np.clip(a1, -self.a_max, self.a_max)
        return self.x


@dataclass
class AdmittanceParams:
    """Everything of the admittance controller but the zones (pairs: [translational, rotational])."""

    v_max: object = field(default_factory=lambda: [0.25, 0.5])   # m/s, rad/s (ASSUMPTION)
    a_max: object = field(default_factory=lambda: [2.0, 5.0])    # m/s^2, rad/s^2 (ASSUMPTION)
    user: UserWrenchParams = field(default_factory=UserWrenchParams)

    def validate(self) -> None:
        per_axis(self.v_max, "v_max", strict=True)
        per_axis(self.a_max, "a_max", strict=True)
        self.user.validate()


@dataclass
class AdmittanceOutput:
    """The set-point for the next period and what produced it."""

    active: bool             # hand guiding (or its braking) is the set-point source
    x: np.ndarray            # x_d,Adm [m, rad]
    xd: np.ndarray           # Kardan rates [m/s, rad/s]
    xdd: np.ndarray          # [m/s^2, rad/s^2]

    def twist(self) -> tuple[np.ndarray, np.ndarray]:
        """(xdot, xddot): the rates as twist and its derivative (base frame), as the loop takes them."""
        return twist_from_pose_rates(self.x, self.xd, self.xdd)

    zone: int                # index of the zone (0 = first); -1 while inactive
    w_user: np.ndarray       # w_Adm of (5.9) as used [N, N m]
    limited: np.ndarray      # (6,) bool: a velocity, acceleration or hard-box limit acted


class AdmittanceController:
    """Hand guiding: enable at the current set-point, step once per period, disable by braking.

    ``step(w, x_d, xdot_d, xddot_d)`` takes the measured wrench of period k and the set-point in
    force at period k (pose, twist and its derivative) and returns the set-point for period k + 1 (the wrench of a period can only
    act on the next one). Inactive, it follows the given set-point. ``disable()`` ignores the user
    from then on and brakes the virtual velocity at a_max; the output stays active until it is at
    rest, so handing the set-point back is without a jump in pose or velocity.
    """

    def __init__(self, robot, dt: float, params: AdmittanceParams | None = None, zones: ZoneSet | None = None):
        self.robot, self.dt = robot, dt
        self.params = params or AdmittanceParams()
        self.params.validate()
        self.zones = zones or thesis_zones(robot.home)
        self.user = UserWrench(robot, dt, self.params.user)
        self.system = VirtualSystem(self.zones, dt, self.params.v_max, self.params.a_max, self._box())
        self.enabled = False
        self.braking = False
        self._reset_pending = False

    def _box(self):
        return hard_box(self.zones, self.params.user.w_max, self.params.v_max)

    def configure(self, params: AdmittanceParams, zones: ZoneSet, robot=None) -> None:
        """Live change of parameters, zones or the robot (a new payload); the state is kept."""
        params.validate()
        self.params, self.zones = params, zones
        if robot is not None:
            self.robot = self.user.robot = robot
        self.user.set_params(params.user)
        self.system.configure(zones, params.v_max, params.a_max, self._box())

    @property
    def active(self) -> bool:
        return self.enabled or self.braking

    def enable(self) -> None:
        """Start hand guiding at the next step (from the set-point then in force)."""
        if not self.active:
            self._reset_pending = True
        self.enabled, self.braking = True, False

    def disable(self) -> None:
        """End hand guiding: brake to rest, then hand back."""
        if self.enabled:
            self.enabled, self.braking = False, not self._reset_pending
        self._reset_pending = False

    def step(self, w, x_d, xdot_d=None, xddot_d=None, periods: int = 1) -> AdmittanceOutput:
        """One period, or ``periods`` with the wrench held (free-running, when measurements of
        some periods were skipped: the virtual system keeps real time)."""
        x_d = np.asarray(x_d, dtype=float)
        if not self.active:
            self.system.reset(x_d)
            return AdmittanceOutput(False, x_d.copy(), np.zeros(6), np.zeros(6), -1, np.zeros(6),
                                    np.zeros(6, dtype=bool))
        raw = self.user.raw(w, x_d, xdot_d, xddot_d)
        if self._reset_pending:                            # switch-on: no jump, no start-up force
            self._reset_pending = False
            self.system.reset(x_d)
            self.user.reset(raw)
        for _ in range(periods):
            if self.braking:
                self._brake()
                w_user = np.zeros(6)
            else:
                w_user = self.user.update(raw)
                self.system.step(w_user)
        s = self.system
        return AdmittanceOutput(True, s.x.copy(), s.v.copy(), s.a.copy(), s.zone, w_user, s.limited.copy())

    def _brake(self) -> None:
        s = self.system
        dv = np.clip(-s.v, -s.a_max * self.dt, s.a_max * self.dt)
        v1 = s.v + dv
        s.x = s.x + 0.5 * (s.v + v1) * self.dt
        s.a, s.v = dv / self.dt, v1
        s.limited = np.zeros(6, dtype=bool)
        if not np.any(s.v):
            self.braking = False                           # at rest: the next step hands back


# ---- flat parameters (the node's, and the parameter files'): one place for their defaults ----

def default_parameters() -> dict:
    """The flat parameters of the ``admittance_controller`` node with their defaults, derived from
    :class:`AdmittanceParams` and :func:`thesis_zones` (6-vectors as lists of 6 floats)."""
    p, z = AdmittanceParams(), thesis_zones()
    rest, free, wall = z.zones
    six = lambda v: [float(a) for a in per_axis(v, "value")]             # noqa: E731
    return {
        "v_max": six(p.v_max), "a_max": six(p.a_max),
        "T_filter": p.user.T_filter, "dead_band": six(p.user.dead_band), "w_max": six(p.user.w_max),
        "tare_on_enable": p.user.tare_on_enable, "tare_time": p.user.tare_time,
        "inertia_compensation": p.user.inertia_compensation,
        "payload_mass": 0.0, "payload_center_of_gravity": [0.0, 0.0, 0.0],
        "zones.origin": [0.0] * 6, "zones.rest.radius": float(rest.size),
        "zones.rest.c": six(rest.c), "zones.rest.d": six(rest.d), "zones.rest.m": six(rest.m),
        "zones.free.box": six(free.size),
        "zones.free.c": six(free.c), "zones.free.d": six(free.d), "zones.free.m": six(free.m),
        "zones.wall.c": six(wall.c), "zones.wall.d": six(wall.d), "zones.wall.m": six(wall.m),
        "zones.force_margin": 0.0,        # N: the thesis' WFW, of the cable limits themselves
    }


def settings_from(values: dict, robot, check_workspace: bool = True) -> tuple[AdmittanceParams, ZoneSet, object]:
    """(params, zones, robot with the known payload) from flat parameters (missing: defaults).

    The zone origin is the robot's home plus ``zones.origin``. Raises ValueError with the reason
    for an invalid combination, including a virtual workspace that leaves the WFW of the cable
    limits narrowed by ``zones.force_margin`` (:func:`~cdpr_control.control.admittance_zones.force_limits`;
    unless ``check_workspace`` is false: an analysis of the dynamics only)."""
    from cdpr_control.control.admittance_zones import Zone, check_in_workspace

    v = {**default_parameters(), **values}
    params = AdmittanceParams(v_max=v["v_max"], a_max=v["a_max"], user=UserWrenchParams(
        T_filter=v["T_filter"], dead_band=v["dead_band"], w_max=v["w_max"],
        tare_on_enable=v["tare_on_enable"], tare_time=v["tare_time"], inertia_compensation=v["inertia_compensation"]))
    params.validate()
    if not v["payload_mass"] >= 0.0:
        raise ValueError(f"payload_mass must be >= 0 kg, got {v['payload_mass']}")
    cog = np.asarray(v["payload_center_of_gravity"], dtype=float)
    if cog.shape != (3,) or not np.all(np.isfinite(cog)):
        raise ValueError(f"payload_center_of_gravity needs 3 finite values, got {v['payload_center_of_gravity']!r}")
    loaded = robot.with_payload(v["payload_mass"], cog) if v["payload_mass"] else robot
    x_0 = np.asarray(robot.home, dtype=float) + np.asarray(v["zones.origin"], dtype=float)
    zones = ZoneSet((
        Zone("rest", "sphere", v["zones.rest.radius"], v["zones.rest.c"], v["zones.rest.d"], v["zones.rest.m"]),
        Zone("free", "box", v["zones.free.box"], v["zones.free.c"], v["zones.free.d"], v["zones.free.m"]),
        Zone("wall", "outside", None, v["zones.wall.c"], v["zones.wall.d"], v["zones.wall.m"], spring="border")), x_0)
    if v["zones.rest.radius"] >= float(np.min(zones.box[:3])):
        raise ValueError("the rest sphere must lie inside the free box")
    f_min, f_max = force_limits(robot, float(v["zones.force_margin"]))
    if check_workspace:
        check_in_workspace(loaded, zones, params.user.w_max, params.v_max, f_min, f_max)
    return params, zones, loaded


def fitted_settings(values: dict, robot):
    """:func:`settings_from`, but a virtual workspace that leaves the WFW is shrunk to fit
    (:func:`~cdpr_control.control.admittance_zones.fit_in_workspace`: the zones, and where that is
    not enough w_max and v_max too) instead of refused, in the WFW of the cable limits narrowed by
    ``zones.force_margin`` on both sides -> (params, zones, robot with the known
    payload, Clipping or None). ValueError for an invalid set, or where nothing fits."""
    params, zones, loaded = settings_from(values, robot, check_workspace=False)
    f_min, f_max = force_limits(robot, float({**default_parameters(), **values}["zones.force_margin"]))
    zones, w_max, v_max, clipping = fit_in_workspace(loaded, zones, params.user.w_max, params.v_max,
                                                     params.user.dead_band, f_min=f_min, f_max=f_max)
    if clipping is not None and clipping.reach_scale < 1.0:
        params = replace(params, v_max=v_max, user=replace(params.user, w_max=w_max))
        params.validate()
    return params, zones, loaded, clipping

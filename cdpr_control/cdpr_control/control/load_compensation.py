"""Online load identification and load compensation, thesis section 4.1.2 (Fig. 4.5).

Identification: the measured wrench w = -A^T(x_d) f (2.11), with A^T at the desired pose (the
thesis assumes a small pose error), and the commanded acceleration, shifted by the time the
platform needs to follow it, give the platform mass of the vertical force equilibrium

    m̂_p = -w_z / (ẍ_d,z - g)                                         (4.4)

(g = the z component of the gravity vector, -9.81 m/s²), averaged over a moving window (240 ms in
the thesis). Where ẍ_d,z - g comes near zero (the platform falling at nearly 1 g) (4.4) divides
noise by nothing: the estimate then holds its last value.

Compensation: the payload m_c = m̂_p - m_p (m_p the platform's own mass) is compensated by the
wrench w_c = [0 0 -m_c g 0 0 0] (= [0 0 m_c |g| 0 0 0], the negative of its weight). The compliance
C_x = K_x^-1 (4.5) of the operational stiffness (2.22) at x_d and the measured forces, in the sign
convention of :mod:`cdpr_control.model.stiffness` (an external wrench dw displaces the platform by
C_x dw), turns it into the offset that lifts the set-point by the sag the elastic cables allow:

    x_d,LC = C_x w_c                                                  (4.6)

(4.6) is a linearisation at the current pose and forces (``offset_model: tangent``); K_l in K_x is
the linear (2.15) or the tangent of the non-linear (2.16)-(2.17) cable model. The default
(``offset_model: secant``, :func:`secant_offset`) solves the elastic equilibrium at x_d between the
loaded and the unloaded state instead: compensated, the platform does not move, so K_g does not
act, and the progressive cables and the lower cables going slack under the payload make the
tangent at one state miss the step by 10-20 % at 128 kg on the IPAnema 3. Cables measured below
``slack_fraction`` f_min count as slack. x_d,LC is slew-rate limited so that a load step does not
step the command.

Tare: (4.4) takes the force sensors as calibrated; :meth:`LoadCompensation.tare` (at rest, with a
known payload) removes the offset of the estimate there.

Optionally the centre of gravity of the payload follows from the torque part: the payload's
share of the measured wrench, [f_p; τ_p] = w - w_platform (the model wrench of the empty platform
(2.33)), satisfies τ_p = c × f_p; the least-squares c over the window (in the platform frame) is
observable only across f_p (at standstill: c_x, c_y; c_z needs horizontal accelerations), the
minimum-norm solution leaves the unobservable part at zero.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cdpr_control.model import cable
from cdpr_control import kernels
from cdpr_control.control.filters import LowPass
from cdpr_control.control.safety import all_finite
from cdpr_control.model.kinematics import cross, kardan_rate_matrix, rotation_matrix
from cdpr_control.model.stiffness import operational_stiffness

STIFFNESS_MODELS = ("linear", "nonlinear")
OFFSET_MODELS = ("secant", "tangent")
ACCELERATION_SOURCES = ("commanded", "estimated")
# s, h: the estimated velocity's difference quotient. The window-mean acceleration it gives,
# ((z(t) - z(t - h)) - (z(t - T) - z(t - T - h))) / (h T), is the mean over h of the window means of
# the acceleration, so w_z gets the same mean over h (LoadCompensation.base_filter): the ratio (4.4)
# stays exact for a platform swinging at any frequency, and the forward kinematics' noise, which the
# quotient divides by h T, counts 20 times less than with 10 ms (measured: docs/load_compensation.md)
VELOCITY_BASE = 0.2
# The window of (4.4) matched to the platform's swing (LoadCompensation._swing_periods): a platform
# swinging after a load step (under force control the IPAnema 3 at 1.5-2 Hz by tens of mm) has a
# mean acceleration over a window T_filter shorter than its period of the order of the swing's
# amplitude, and the forward kinematics sees only part of it (the elastic model's view of a
# mismatched plant: 66-110 % of the swing at ipanema3 #38), which (4.4) reads as mass. Over a whole
# period of the swing its acceleration, and any error proportional to it, averages to about zero,
# so the window of w_z and of the pose's acceleration spans the last full period of the swing
# (twice the time between the forward kinematics' last two turning points) where that is longer
# than T_filter.
SWING_WINDOW_MAX = 1.0      # s, longest window (a slower swing keeps this one)
SWING_AMPLITUDE = 1e-3      # m, half the z change between the last two extremes: below it no swing
SWING_HYSTERESIS = 2e-4     # m, |z(t) - z(t - h)| beyond this sets the direction of motion (noise: 0.1 mm)
# A window over a swing must not reach back across a load change (docs/load_compensation.md, "The
# swing window over a load step (session 14)"); the thesis has no step detection, its means against
# changing loads is the short window itself (4.1.2). So the thesis' own estimate, (4.4) over T_filter,
# is kept per sample and each one within the window is compared with the latest: over a swing each
# reads the share of the swing's acceleration a that the forward kinematics misses as mass, at most
# m̂ a / |g| (where it misses all of it), so two differ by at most 2 m̂ a / |g|, the swing's own force
# swing over |g|: the range of the measured w_z over a half swing (the acceleration from one extreme
# to the other; the force sensors see the true acceleration, however little of the swing the forward
# kinematics sees). A load change moves w_z one way, so it is in at most one of the last two half
# swings, and the smaller of their two ranges is the swing's; where the change was put down across
# both it is in both, so the bound is also at most the forward kinematics' view of the swing,
# 2 m̂ a_seen / SWING_SEEN_MIN (a_seen the acceleration amplitude of its last half swing; the least
# share of a swing it was measured to see is 66 %, ipanema3 #38 under force control; 0.2 keeps the
# slow swing of tests/control/test_load_comp_estimate.py, seen a fifth, a swing). A load change
# moves the later estimates by the change: the window starts after the latest T_filter estimate that
# differs from the latest by more than LOAD_CHANGE m̂ + that bound / |g| (at least T_filter, the
# thesis' window). LOAD_CHANGE: the noise of a T_filter estimate at rest and the share of the mass a
# change below it may cost. The sample of that estimate is the latest load change the history shows
# (LoadCompensation._load_change, over the whole history, not only the estimates inside the window: a
# window must not jump past a change once the change's estimate leaves its range: session 15, under
# force control with the CFC's internal integral the sag and recovery of a small step turn twice by
# more than 2 mm, a "swing" whose window then jumped back into the payload's ramp, ipanema3 #24 9.6 %;
# docs/load_compensation.md, "The window after the load step with the internal integral (session 15)").
LOAD_CHANGE = 0.02
SWING_SEEN_MIN = 0.2
SECANT_TOLERANCE = 1e-3    # relative residual |A^T (f_U - f) + w_c| / (|w_c| + 1 N) of secant_offset
KC_RCOND = 1e-9      # singular values of K_c below this share of the largest: directions no tensed cable stiffens
REFERENCE_FRACTION = 0.05   # |m_c| below this share of m_p: an unloaded state, its forces the reference
COG_DECIMATION = 10      # the centre of gravity (slow) takes every 10th period into its window


def _floats(v) -> list[float]:
    """The entries of a flat vector as a list of floats (numpy's float64 cast of them)."""
    return np.asarray(v, dtype=float).tolist()


def mass_estimate(w_z: float, xddot_z: float, g_z: float, guard: float) -> float | None:
    """m̂_p = -w_z / (ẍ_d,z - g) (4.4) [kg]; None where |ẍ_d,z - g| < guard [m/s²] (held)."""
    denominator = xddot_z - g_z
    if not abs(denominator) >= guard or not math.isfinite(w_z):
        return None
    return -w_z / denominator


class MovingAverage:
    """Mean of the last n samples (n = round(T / dt), at least 1); the first sample fills the window,
    so the average starts there instead of rising from zero. A running sum, re-summed once per
    window against rounding drift.

    The window and the sum are plain floats (:meth:`push`, every period in the load compensation):
    the same element-wise arithmetic as numpy's on arrays of 2 or m numbers, without the call
    overhead. The fills and the re-sum stay numpy's ``sum(axis=0)`` of the (n, size) window, whose
    summation order (pairwise for size 1) a Python loop would not reproduce."""

    def __init__(self, T: float, dt: float, size: int = 1):
        if not (T >= 0.0 and dt > 0.0):
            raise ValueError(f"need T >= 0 s and dt > 0 s, got T={T}, dt={dt}")
        self.dt, self.size = dt, size
        self.buffer: list[list[float]] | None = None     # n rows of size floats, a ring
        self.sum: list[float] | None = None
        self.index = 0
        self.set_window(T)

    def set_window(self, T: float) -> None:
        """Change the window; a running average restarts filled with its current mean (no jump)."""
        if not T >= 0.0:
            raise ValueError(f"window must be >= 0 s, got {T}")
        mean = self.mean if self.buffer is not None else None
        self.T = T
        self.n = max(int(round(T / self.dt)), 1)
        if mean is not None:
            self.reset(mean)

    def reset(self, value=None) -> None:
        if value is None:
            self.buffer = self.sum = None
        else:
            buffer = np.tile(np.asarray(value, dtype=float), (self.n, 1))
            self.buffer, self.sum = buffer.tolist(), buffer.sum(axis=0).tolist()
        self.index = 0

    @property
    def mean(self) -> np.ndarray | None:
        return None if self.buffer is None else np.array(self.sum) / self.n

    def update(self, value) -> np.ndarray:
        self.push(np.asarray(value, dtype=float).reshape(self.size).tolist())
        return self.mean

    def push(self, value: list[float]) -> list[float]:
        """:meth:`update` of ``size`` floats -> the mean as floats. The list itself goes into the
        window: the caller passes one it does not change afterwards."""
        if self.buffer is None:
            self.reset(value)
        else:
            old = self.buffer[self.index]
            self.sum = [s + (v - o) for s, v, o in zip(self.sum, value, old)]
            self.buffer[self.index] = value
            self.index = (self.index + 1) % self.n
            if self.index == 0:
                self.sum = np.array(self.buffer).sum(axis=0).tolist()
        n = self.n
        return [s / n for s in self.sum]


def cable_stiffness_model(robot, ik, f, model: str, f_slack: float = 0.0) -> np.ndarray:
    """K_l (m,) [N/m] of (2.20) at the free lengths l_t = q + l_0 (2.14) of the IK ``ik``:

    linear: k_spec / l_t (2.15) with the nominal k_spec (the thesis' model in 4.1.3);
    nonlinear: df/dΔq of the progressive cable (2.16)-(2.17) at the forces f.

    A slack cable carries nothing and has no stiffness, but its measured force is sensor noise and
    offset around zero, where (2.17) jumps from 0 to k0 / l_t: a slack cable read at a few newtons
    would count as fully stiff. Below ``f_slack`` [N] the stiffness is therefore scaled by f / f_slack
    (zero at f <= 0, the full value from f_slack on).
    """
    l_t = cable.total_free_length(robot, ik.q)
    if model == "linear":
        k = robot.cable.k_spec_nominal / l_t
    elif model == "nonlinear":
        k = cable.tangent_stiffness(robot, f, l_t)
    else:
        raise ValueError(f"stiffness model must be one of {STIFFNESS_MODELS}, got {model!r}")
    if f_slack > 0.0:
        k = k * np.clip(np.asarray(f, dtype=float) / f_slack, 0.0, 1.0)
    return k


def compliance(ik, f, k_l) -> np.ndarray:
    """C_x = K_x^-1 (4.5) of K_x = K_g + K_c (2.22) (stiffness.operational_stiffness) [(6, 6)].

    Twist coordinates (dr, dθ about the base axes), as K_x. Raises numpy.linalg.LinAlgError where
    K_x is singular (a slack configuration).
    """
    return np.linalg.inv(operational_stiffness(ik, f, k_l))


def load_offset(C_x, m_c: float, gravity, cog=None, R=None) -> np.ndarray:
    """x_d,LC = C_x w_c (4.6) [m, m, m, rad, rad, rad] (twist coordinates) for a payload m_c [kg].

    w_c is the wrench that compensates the payload's weight m_c g (gravity (3,) the base-frame
    vector, so w_c = [0 0 m_c |g| 0 0 0] = -m_c [g; 0] as in the thesis); with ``cog`` (3,) the
    payload's centre of gravity in the platform frame and R the platform orientation, also its
    moment -(R c) × m_c g. C_x w_c is the displacement the cables would allow under w_c: the
    platform sinks by it under the payload, so the set-point is raised by it.
    """
    return np.asarray(C_x) @ compensating_wrench(m_c, gravity, cog, R)


def compensating_wrench(m_c: float, gravity, cog=None, R=None) -> np.ndarray:
    """w_c = -m_c [g; (R c) × g] (6,) [N, N m] of (4.6): the negative of the payload's weight and,
    with its centre of gravity ``cog`` (platform frame) and orientation R, of its moment."""
    weight = m_c * np.asarray(gravity, dtype=float)
    w_c = np.zeros(6)
    w_c[:3] = -weight
    if cog is not None:
        w_c[3:] = -cross(np.asarray(R, dtype=float) @ np.asarray(cog, dtype=float), weight)
    return w_c


def secant_offset(robot, ik, f, w_c, f_ref=None, f_slack: float | None = None, iterations: int = 6,
                  settlement=None) -> np.ndarray:
    """The set-point offset c (6,) [m, rad] (twist coordinates) that carries the compensating wrench
    w_c (6,) [N, N m] at the pose of ``ik``, from the loaded state with the measured forces f (m,):
    the non-linear (secant) form of (4.5)-(4.6) at a fixed platform pose.

    Compensated, the platform stays at x_d and only the command moves: raising it by c changes the
    commanded cable lengths by -A c (A = (A^T)^T with A^T = ``ik.AT`` of (2.11); the length
    Jacobian is -A), so each cable's elongation at x_d grows by (A c)_i; the cable directions do not
    change, so the geometric stiffness K_g of (2.22) does not enter, and to first order
    c = K_c^-1 w_c with K_c = A^T K_l A. The cable law (2.17) is progressive and cables go slack
    under a payload, so the tangent at the loaded forces misses the unloaded state the command
    must reproduce; this solves the elastic equilibrium between the two states instead:

        A^T (f_U(c) - f) = -w_c,   f_U,i = f_i(Δq_i - (A c)_i)   (tensed: Δq_i of f_i by (3.7)),

    by Newton's method with the Jacobian K_c at f_U. A cable measured below ``f_slack`` [N] is
    slack: its elongation is not observable from its force, so its unloaded force is taken from
    ``f_ref`` (m,) (the forces of a known unloaded state, e.g. at the tare; None: zero);
    f_slack None: 20 % of the robot's f_min. ``settlement`` (m,) [m]: the growth of the unstretched
    lengths since the unloaded state (cable settlement under load, section 4.1.3; see
    :class:`SettlementModel`): the command shortens each cable by it as well,
    e_U = e_L - A c + s.

    With fewer than six tensed cables (the Mini under IK-only control: its lower cables, pre-tensed
    to 5 N, go slack under any payload worth compensating, and the platform hangs on the four upper
    ones) K_c has rank below 6: the offsets along its null space do not change a tensed cable's
    elongation, so they do not change what the cables carry. Each Newton step is then the
    minimum-norm least-squares one (the pseudo-inverse of K_c), which leaves them at zero; the
    equilibrium is still required to the tolerance, so a wrench the tensed cables cannot carry is
    refused as not converged.

    Raises numpy.linalg.LinAlgError where no cable is tensed or Newton's method does not converge:
    the offset is then not determined by the measurement (a platform swinging with slack cables).
    """
    f = np.asarray(f, dtype=float)
    slack = f < (0.2 * float(np.min(robot.cable.f_min)) if f_slack is None else f_slack)
    l_t = cable.total_free_length(robot, ik.q)
    AT = ik.AT
    e_L = cable.elongation_from_force(robot, np.maximum(f, 0.0), l_t)
    f_fixed = np.zeros_like(f) if f_ref is None else np.maximum(np.asarray(f_ref, dtype=float), 0.0)
    w_c = np.asarray(w_c, dtype=float)
    if not np.any(~slack):
        raise np.linalg.LinAlgError("no tensed cable: the offset is not observable")
    if settlement is not None:
        e_L = e_L + np.asarray(settlement, dtype=float)
    c = np.zeros(6)
    scale = np.linalg.norm(w_c) + 1.0
    for _ in range(iterations + 1):
        e_U = e_L - AT.T @ c
        f_U = np.where(slack, f_fixed, cable.force_from_elongation(robot, e_U, l_t))
        residual = AT @ (f_U - f) + w_c
        if np.linalg.norm(residual) <= SECANT_TOLERANCE * scale:
            return c
        k = np.where(slack, 0.0, cable.tangent_stiffness(robot, f_U, l_t))
        K_c = (AT * k) @ AT.T
        # minimum-norm step: with fewer than six tensed cables K_c is singular (see above); the
        # relative cut-off drops the directions the tensed cables do not stiffen
        c = c + np.linalg.lstsq(K_c, residual, rcond=KC_RCOND)[0]
    raise np.linalg.LinAlgError("secant offset: Newton's method did not converge (the tensed cables do not "
                                "carry the compensating wrench)")


class SettlementModel:
    """Cable settlement under load (section 4.1.3: 9.2 mm lasting error after 128 kg), predicted
    from the measured forces: a cable that carries more than the force it has settled to grows
    by a lasting s_i towards ratio * l_t,i (f_i - f_settled,i) / k0 with time constant T, and s
    never shrinks. ratio and T come from an identification with an external pose measurement
    (cdpr_tools.identify.settlement); ratio 0 switches the model off.

    The settlement is not observable from the forces and encoders at a standstill (the payload's
    weight fixes the forces; the sinking platform changes them only through the cable directions),
    so the compensation needs this model of the force history.
    """

    def __init__(self, robot, dt: float, ratio: float = 0.0, T: float = 2.0):
        self.robot, self.dt = robot, dt
        self.s = np.zeros(robot.m)
        self.f_settled: np.ndarray | None = None
        self.set_params(ratio, T)

    def set_params(self, ratio: float, T) -> None:
        """T may be an array (k, 1) of time constants: s is then (k, m), one row each (for a fit)."""
        self.ratio, self.T = float(ratio), T
        self.alpha = 1.0 - np.exp(-self.dt / np.asarray(T, dtype=float))

    def reset(self, f_settled) -> None:
        """The cables have settled to the forces f_settled (m,) [N] (at power-on, or at a tare)."""
        self.s = np.zeros(self.robot.m)
        self.f_settled = np.array(f_settled, dtype=float)

    def update(self, f, l_t) -> np.ndarray:
        """One period with the (window-mean) measured forces f (m,) [N] and free lengths l_t (m,) [m]
        -> s (m,) [m]."""
        if self.ratio == 0.0 or self.f_settled is None:
            return self.s
        target = self.ratio * np.asarray(l_t) * np.maximum(np.asarray(f) - self.f_settled, 0.0) / self.robot.cable.k0
        self.s = self.s + self.alpha * np.maximum(target - self.s, 0.0)
        return self.s


def settlement_offset(ik, s, phi) -> np.ndarray:
    """The pose offset (6,) [m, rad] that shortens the commanded cables by the settlement s (m,) [m]:
    a twist dx changes the lengths by dq = -(A^T)^T dx (kinematics.cable_velocities), so
    dx = ((A^T)^T)^+ s (least squares over the m cables) gives IK(x_d + dx) = q - s, and cables
    that settled (longer by s_i at the same force, section 4.1.3) hold the platform where it was.
    The part of s no rigid motion gives is a change of the internal forces, which the cable force
    control takes."""
    dx = np.linalg.lstsq(np.asarray(ik.AT, dtype=float).T, np.asarray(s, dtype=float), rcond=None)[0]
    return twist_to_pose_offset(dx, phi)


def twist_to_pose_offset(dx, phi) -> np.ndarray:
    """A small displacement in twist coordinates (dr, dθ) as a pose offset (dr, dφ) in Kardan angles
    at the orientation φ: dθ = H(φ) dφ (kinematics.kardan_rate_matrix)."""
    dx = np.asarray(dx, dtype=float)
    return np.concatenate((dx[:3], np.linalg.solve(kardan_rate_matrix(phi), dx[3:])))


def _rotate(phi_x: float, phi_y: float, phi_z: float, px: float, py: float, pz: float) -> tuple[float, float, float]:
    """R p for R = Rx Ry Rz of Kardan angles (kinematics.rotation_matrix) in scalar math: equal to
    rotation_matrix(phi) @ p up to the rounding of the sums."""
    ca, cb, cc = math.cos(phi_x), math.cos(phi_y), math.cos(phi_z)
    sa, sb, sc = math.sin(phi_x), math.sin(phi_y), math.sin(phi_z)
    sa_sb, ca_sb = sa * sb, ca * sb
    return (cb * cc * px + -cb * sc * py + sb * pz,
            (ca * sc + sa_sb * cc) * px + (ca * cc - sa_sb * sc) * py + -sa * cb * pz,
            (sa * sc - ca_sb * cc) * px + (sa * cc + ca_sb * sc) * py + ca * cb * pz)


def payload_wrench(robot, x, xdot, xddot, mass: float, cog=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Wrench (6,) of a point-mass payload [kg] at ``cog`` (platform frame) on the moving platform,
    about the platform origin in the base frame: what it adds to the w of (2.10), (2.33):

        f = m (g - a_c),  τ = (R c) × f,  a_c = a + ω̇ × R c + ω × (ω × R c) .
    """
    return payload_wrench_of_mass(payload_kinematics(robot, x, xdot, xddot, cog), mass)


def payload_kinematics(robot, x, xdot, xddot, cog=(0.0, 0.0, 0.0)) -> tuple[float, ...]:
    """The mass-free part of :func:`payload_wrench`: R c and g - a_c as six floats. The force
    distribution node keeps it while the set-point and the cog repeat (the identified mass changes
    every period)."""
    # scalar math: the force distribution node runs this every period (numpy: 50 us, this: 4)
    phi_x, phi_y, phi_z = np.asarray(x, dtype=float)[3:].tolist()
    cx, cy, cz = _rotate(phi_x, phi_y, phi_z, *np.asarray(cog, dtype=float).tolist())   # R c
    wx, wy, wz = np.asarray(xdot, dtype=float)[3:].tolist()
    ax, ay, az, dwx, dwy, dwz = np.asarray(xddot, dtype=float).tolist()
    vx, vy, vz = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx           # ω × R c
    a = (ax + dwy * cz - dwz * cy + wy * vz - wz * vy,                               # a + ω̇ × R c + ω × (ω × R c)
         ay + dwz * cx - dwx * cz + wz * vx - wx * vz,
         az + dwx * cy - dwy * cx + wx * vy - wy * vx)
    gx, gy, gz = robot.gravity.tolist()
    return cx, cy, cz, gx - a[0], gy - a[1], gz - a[2]


def payload_wrench_of_mass(kinematics: tuple[float, ...], mass: float) -> np.ndarray:
    """:func:`payload_wrench` of the mass-free part ``kinematics`` (:func:`payload_kinematics`):
    f = m (g - a_c), τ = (R c) × f."""
    cx, cy, cz, ex, ey, ez = kinematics
    fx, fy, fz = mass * ex, mass * ey, mass * ez
    return np.array([fx, fy, fz, cy * fz - cz * fy, cz * fx - cx * fz, cx * fy - cy * fx])


@dataclass
class LoadCompensationParams:
    """Parameters of :class:`LoadCompensation` (the node's defaults are these)."""

    enabled: bool = True            # x_d,LC out (the identification runs regardless)
    T_filter: float = 0.24          # s, moving-average window of the mass estimate (section 4.1.2)
    time_shift: float = 0.01        # s, the commanded acceleration is delayed by this before (4.4) (T_d,w of (3.25))
    accel_guard: float = 2.0        # m/s², |ẍ_z - g| below this holds the estimate (4.4)
    acceleration_source: str = "estimated"   # ẍ_z of (4.4): commanded (time-shifted, thesis) or estimated (FK pose)
    offset_model: str = "secant"    # x_d,LC: secant (the elastic equilibrium at x_d, secant_offset) or tangent (C_x w_c (4.6))
    stiffness_model: str = "nonlinear"   # tangent model: K_l in K_x (2.22): linear (2.15) or nonlinear (2.16)-(2.17)
    slack_fraction: float = 0.2     # measured (window-mean) cable forces below this share of f_min count as (partly) slack
    platform_mass: float = 0.0      # kg, the platform's own mass m_p; 0 = the robot file's
    torque: bool = False            # also compensate the payload's moment (needs the identified cog)
    cog_min_mass: float = 5.0       # kg, the payload's cog is identified (and published) above this m_c
    T_output: float = 1.0           # s, PT1 on C_x w_c: keeps the compensation loop below the platform modes
    v_max: float = 0.1              # m/s, rate limit of the translation of x_d,LC (above the output PT1's rate: docs/load_compensation.md)
    tare_at_start: bool = False     # tare the estimate once (4.4) is in its final form (start at a known payload)
    tare_payload: float = 0.0       # kg, the payload known to be on the platform at a tare
    omega_max: float = 0.1          # rad/s, rate limit of the rotation of x_d,LC
    settlement_ratio: float = 0.0   # -, cable settlement model (SettlementModel, identified); 0: off
    settlement_time: float = 2.0    # s, its time constant
    # the ratio was identified on this robot (`cdpr identify settlement -o` writes true): the model's
    # s then also lengthens the forward kinematics' cables (PoseEstimator.settlement, cause A of
    # docs/load_compensation.md "The settlement in the pose estimator"), and with x_d,LC off (force
    # control) the output is settlement_offset of s (docs/load_compensation.md, session 15); false
    # (default): s acts in x_d,LC only, as an assumed ratio over-compensates a plant that does not settle
    settlement_identified: bool = False

    def validate(self) -> None:
        if self.acceleration_source not in ACCELERATION_SOURCES:
            raise ValueError(f"acceleration_source must be one of {ACCELERATION_SOURCES}, "
                             f"got {self.acceleration_source!r}")
        if self.offset_model not in OFFSET_MODELS:
            raise ValueError(f"offset_model must be one of {OFFSET_MODELS}, got {self.offset_model!r}")
        if self.stiffness_model not in STIFFNESS_MODELS:
            raise ValueError(f"stiffness_model must be one of {STIFFNESS_MODELS}, got {self.stiffness_model!r}")
        for name in ("T_filter", "time_shift", "accel_guard", "platform_mass", "cog_min_mass", "T_output", "v_max",
                     "omega_max", "slack_fraction", "tare_payload", "settlement_ratio"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if not (np.isfinite(self.settlement_time) and self.settlement_time > 0.0):
            raise ValueError(f"settlement_time must be finite and > 0 s, got {self.settlement_time}")
        if self.accel_guard <= 0.0:
            raise ValueError("accel_guard must be > 0 m/s² (else (4.4) may divide by zero)")


class LoadCompensation:
    """Load identification (4.4) and compensation (4.5)-(4.6), one control period per update.

    State after update: ``m_hat`` (filtered total platform mass [kg]), ``m_c`` (payload [kg]),
    ``guarded`` (the estimate held: (4.4) near its singularity or invalid input), ``cog``
    (the payload's centre of gravity in the platform frame [m], None until m_c > cog_min_mass),
    ``x_target`` (C_x w_c before the rate limit, as a pose offset) and ``x_lc`` (the output).
    """

    def __init__(self, robot, dt: float, params: LoadCompensationParams | None = None):
        self.robot, self.dt = robot, dt
        self.wrench_filter = MovingAverage(0.24, dt, size=2)    # w_z and the commanded ẍ_z of (4.4)
        self.cog_filter = MovingAverage(0.24, dt * COG_DECIMATION, size=12)   # normal equations of τ = c × f
        self.force_filter = MovingAverage(0.24, dt, size=robot.m)  # f for K_l: the same window, noise averaged out
        self.m_tare = 0.0                                      # kg, subtracted from (4.4) (see tare)
        self.f_ref: list[float] | None = None                  # forces of the last unloaded state
        self.tared = False
        self.periods = 0
        self.samples = 0
        self.delay: list[list[float]] | None = None            # n + 1 rows of x_d, ẋ_d, ẍ_d (18 floats)
        self.delay_index = 0
        self.z_history: list[float] = []                       # estimated z of the longest window + h
        self._velocity_base = max(int(round(VELOCITY_BASE / dt)), 1)   # h, periods
        self._n_max = max(int(round(SWING_WINDOW_MAX / dt)), 1)
        self.w_cumulative = 0.0                                # running sum of w_z (for any window)
        self.c_history: list[float] = [0.0] * self._velocity_base   # its last h values
        self.d_history: list[float] = []                       # sums of the cumulative sum over h
        self.direction = 0                                     # z rising (+1) or falling (-1) by SWING_HYSTERESIS
        self.extremes: list[tuple[int, float]] = []            # (sample, z) of the last three turning points
        self.window_n: int | None = None                       # samples of the last window of (4.4)
        self.w_history: list[float] = []                       # w_z per sample (the longest window + 1)
        self.m_short: list[float] = []                         # (4.4) over T_filter per sample (the longest window + 1)
        self.samples_seen = 0                                  # samples of the estimated pose
        self.pose_acceleration = False                         # (4.4) took the estimated pose's ẍ_z
        self.m_hat: float | None = None
        self.m_c = 0.0
        self.guarded = True
        self.cog: np.ndarray | None = None
        self.x_target = np.zeros(6)
        self.output_filter = LowPass(0.3, dt)
        self.output_filter.reset(np.zeros(6))
        self.x_lc = np.zeros(6)
        self.rate_limited = np.zeros(6, dtype=bool)
        self.slack_cables = 0                                  # window-mean forces below f_slack
        self._f_min_low = float(np.min(robot.cable.f_min))    # (f_slack's, every period: np.min costs 3 us)
        self.settlement = SettlementModel(robot, dt)
        self.set_params(params or LoadCompensationParams())

    def set_params(self, p: LoadCompensationParams) -> None:
        p.validate()
        self.params = p
        self.wrench_filter.set_window(p.T_filter)
        self.force_filter.set_window(p.T_filter)
        self.cog_filter.set_window(p.T_filter)
        self.output_filter.set_time_constant(p.T_output)
        self.settlement.set_params(p.settlement_ratio, p.settlement_time)
        n = int(round(p.time_shift / self.dt))
        if self.delay is None or len(self.delay) != n + 1:
            last = None if self.delay is None else self.delay[(self.delay_index - 1) % len(self.delay)]
            self.delay = None if last is None else [list(last) for _ in range(n + 1)]
            self.delay_index = 0
            self._delay_n = n
        if not p.enabled:
            self.x_lc = np.zeros(6)          # re-enabling starts from zero
            self.output_filter.reset(np.zeros(6))

    @property
    def f_slack(self) -> float:
        """N, measured forces below this count as (partly) slack: slack_fraction of the robot's f_min."""
        return self.params.slack_fraction * self._f_min_low

    def _reference_forces(self) -> np.ndarray:
        """The unloaded forces for the slack cables of :func:`secant_offset`: those of the last window
        with (nearly) no payload, else f_min (what a force distribution keeps an unloaded robot at)."""
        return np.array(self.f_ref) if self.f_ref is not None else np.broadcast_to(
            np.asarray(self.robot.cable.f_min, dtype=float), (self.robot.m,))

    @property
    def m_p(self) -> float:
        return self.params.platform_mass or self.robot.platform.mass

    def tare(self, payload: float | None = None) -> float | None:
        """Tare the estimate at a known state: from now on the current estimate reads m_p + payload
        (default ``tare_payload``). The offset it removes is that of the force sensors (3.29) and of
        the model (anchor points, m_p) in (4.4), which read as payload. Take it at rest, with the
        payload known (e.g. at home after power-on, empty). Returns the offset [kg] (None, and no
        change, while the estimate is held or not yet available)."""
        payload = self.params.tare_payload if payload is None else float(payload)
        if self.m_hat is None or self.guarded or not np.isfinite(payload):
            return None
        self.m_tare += self.m_hat - (self.m_p + payload)
        self.m_hat = self.m_p + payload
        self.m_c = payload
        self.tared = True
        if self.force_filter.mean is not None:
            self.settlement.reset(self.force_filter.mean)       # settled to the forces of the known state
        return self.m_tare

    def _shifted(self, x_d, xdot_d, xddot_d) -> list[float]:
        """The set-point of time_shift ago, [x_d, ẋ_d, ẍ_d] as 18 floats (a ring buffer; it starts
        filled with the first one)."""
        sample = _floats(x_d) + _floats(xdot_d) + _floats(xddot_d)
        if self.delay is None:
            self.delay = [list(sample) for _ in range(self._delay_n + 1)]
        self.delay[self.delay_index] = sample
        self.delay_index = (self.delay_index + 1) % len(self.delay)
        return self.delay[self.delay_index]                   # written _delay_n periods ago

    def _swing_periods(self) -> int:
        """n, the window of (4.4) in periods: T_filter, or the last full period of the platform's
        swing where that is longer (at most SWING_WINDOW_MAX; see SWING_WINDOW_MAX). The swing's
        turning points are where z(t) - z(t - h) changes sign (by SWING_HYSTERESIS, so that the
        forward kinematics' noise at rest turns nothing); its period is twice the time between the
        last two (the latest half swing: a swing that decays or changes its frequency after a step
        is matched as soon as it turns), and it counts as a swing where the last two half swings
        each move z by 2 SWING_AMPLITUDE or more; the window starts after the latest load change
        (:meth:`_load_change`)."""
        zh, h = self.z_history, self._velocity_base
        if len(zh) > h:
            v = zh[-1] - zh[-1 - h]
            direction = 1 if v > SWING_HYSTERESIS else -1 if v < -SWING_HYSTERESIS else self.direction
            if direction != self.direction:
                # the turning point: the extreme z of the last h samples; the first motion from rest
                # (no direction yet) turns there too, so that the first half swing after a step is one
                previous = self.direction or -direction
                recent = zh[-1 - h:]
                k = max(range(len(recent)), key=recent.__getitem__) if previous > 0 else \
                    min(range(len(recent)), key=recent.__getitem__)
                self.extremes = (self.extremes + [(self.samples_seen - len(recent) + k, recent[k])])[-3:]
                self.direction = direction
        n = self.wrench_filter.n
        # a swing: the last two half swings both large enough (a single excursion, such as the sag
        # and recovery of a load step under force control, turns once from rest and is not one: a
        # window over it would reach back across the load change), and not stopped (a turning point
        # within the longest window): at rest again, the next load step is read with T_filter's latency
        e = self.extremes
        if (len(e) == 3 and min(abs(e[2][1] - e[1][1]), abs(e[1][1] - e[0][1])) >= 2.0 * SWING_AMPLITUDE
                and self.samples_seen - e[2][0] <= self._n_max):
            n_swing = min(2 * (e[2][0] - e[1][0]), self._n_max)
            # the swing's force swing: the smaller of its last two half swings' (a load change, one
            # way, is in at most one of them; a swing goes both ways)
            force_swing = min(self._force_swing(e[0][0], e[1][0]), self._force_swing(e[1][0], e[2][0]))
            # ... and at most what the seen swing's acceleration allows where the forward kinematics
            # sees SWING_SEEN_MIN of it (a load change split over both half swings is in both ranges)
            half = max(e[2][0] - e[1][0], 1) * self.dt
            seen = 0.5 * abs(e[2][1] - e[1][1]) * (math.pi / half) ** 2          # m/s², amplitude
            m_hat = abs(self.m_hat) if self.m_hat is not None else self.m_p
            force_swing = min(force_swing, 2.0 * m_hat * seen / SWING_SEEN_MIN)
            if n_swing > n:
                # the window starts after the latest load change the whole history shows (session 15:
                # not only the T_filter estimates inside the window, which let it jump past the change)
                change = self._load_change(force_swing)
                n = max(n, n_swing if change is None else min(n_swing, self.samples_seen - 1 - change))
        return n

    def _force_swing(self, first: int, last: int) -> float:
        """The range [N] of the measured w_z from sample ``first`` to ``last`` (a half swing: the
        acceleration from one extreme to the other, so 2 m a), over what the history holds."""
        w, end = self.w_history, self.samples_seen - 1                              # w[-1]: sample end
        lo, hi = max(len(w) - 1 - (end - first), 0), len(w) - 1 - (end - last)
        return max(w[lo:hi + 1]) - min(w[lo:hi + 1]) if hi >= lo else 0.0

    def _load_change(self, force_swing: float) -> int | None:
        """The sample of the latest load change the history shows (None where it shows none): the
        latest (4.4) over T_filter (m_short, over the whole history of the longest window, not only
        the estimates inside a candidate window) that differs from the latest by more than LOAD_CHANGE
        of the estimated mass plus force_swing / |g| (force_swing [N]: the swing's own, see
        LOAD_CHANGE), as that estimate then still saw the load before the change; a sample without an
        estimate (NaN) counts as one. A window starts after it."""
        m = np.asarray(self.m_short)
        if not len(m):
            return None
        scale = abs(self.m_hat) if self.m_hat is not None else self.m_p
        limit = LOAD_CHANGE * scale + force_swing / abs(float(self.robot.gravity[2]))
        differs = np.flatnonzero(~(np.abs(m - m[-1]) <= limit))              # NaN differs too
        return self.samples_seen - len(m) + int(differs[-1]) if len(differs) else None

    def _estimated_acceleration(self, z: float, w_z: float) -> tuple[float, float] | None:
        """(w_z, ẍ_z) of (4.4) from the estimated pose: the mean vertical acceleration over the
        window, (v(t) - v(t - T)) / T with v a difference quotient over VELOCITY_BASE h, is the mean
        over h of the window means of the acceleration (see VELOCITY_BASE), and w_z (this period's
        sample) gets the same means; the window is :meth:`_swing_periods`. None until the history
        spans the window and h."""
        h = self._velocity_base
        n_max = max(self._n_max, self.wrench_filter.n)          # a T_filter beyond SWING_WINDOW_MAX: its own
        self.samples_seen += 1
        self.z_history.append(z)
        del self.z_history[:-(n_max + h + 1)]
        # D(k) = sum over the last h of C, the cumulative sum of w_z: (D(k) - D(k - n)) / (h n) is
        # the mean over h of the n-window means of w_z, for any n
        self.w_history.append(w_z)
        del self.w_history[:-(n_max + 1)]
        self.w_cumulative += w_z
        self.c_history.append(self.w_cumulative)
        previous = self.d_history[-1] if self.d_history else 0.0
        self.d_history.append(previous + self.w_cumulative - self.c_history.pop(0))
        del self.d_history[:-(n_max + 1)]
        n_short = self.wrench_filter.n
        short = self._window_means(n_short)                      # (4.4)'s window of the thesis
        self.m_short.append(self._window_mass(short))
        del self.m_short[:-(n_max + 1)]
        n = self._swing_periods()
        window = short if n == n_short else self._window_means(n)
        if window is not None:
            self.window_n = n
        return window

    def _window_means(self, n: int) -> tuple[float, float] | None:
        """(w_z, ẍ_z) over the last n samples (see :meth:`_estimated_acceleration`), None until the
        history spans n and h."""
        h, zh, d = self._velocity_base, self.z_history, self.d_history
        if len(zh) < n + h + 1 or len(d) < n + 1:
            return None
        a = ((zh[-1] - zh[-1 - h]) - (zh[-1 - n] - zh[-1 - n - h])) / (h * self.dt * n * self.dt)
        return (d[-1] - d[-1 - n]) / (h * n), a

    def _window_mass(self, window: tuple[float, float] | None) -> float:
        """(4.4) of a window's means (:meth:`_window_means`) with the estimated pose's acceleration,
        untared [kg]; NaN without a window or near (4.4)'s singularity."""
        estimate = None if window is None else mass_estimate(*window, float(self.robot.gravity[2]),
                                                             self.params.accel_guard)
        return float("nan") if estimate is None else float(estimate)

    def identify(self, x_d, xdot_d, xddot_d, f, AT, x=None) -> None:
        """One sample of (4.4) and of the cog's normal equations into the moving averages.

        x: the estimated pose (forward kinematics), needed for acceleration_source = estimated; only
        its z enters, so its position (3,) will do.
        """
        shifted = self._shifted(x_d, xdot_d, xddot_d)
        w = -np.asarray(AT) @ np.asarray(f, dtype=float)                    # (2.11) at x_d
        if self.m_hat is None:
            self.m_hat = self.m_p
        w_floats = w.tolist()
        if not all_finite(w_floats):
            self.guarded = True
            return                                                           # hold the estimate
        w_z, a = self.wrench_filter.push([w_floats[2], shifted[14]])        # means over the window (ẍ_z)
        self.pose_acceleration = False
        if self.params.acceleration_source == "estimated" and x is not None and math.isfinite(x[2]):
            estimated = self._estimated_acceleration(float(x[2]), w_floats[2])
            if estimated is not None:                  # commanded until the history spans a window and h
                w_z, a = estimated                     # both averaged alike: (4.4) exact for any motion
                self.pose_acceleration = True
        estimate = mass_estimate(w_z, a, float(self.robot.gravity[2]), self.params.accel_guard)
        self.guarded = estimate is None
        if self.guarded:
            return                                                           # hold the estimate
        self.m_hat = float(estimate) - self.m_tare
        self.samples += 1
        if self.samples % COG_DECIMATION:
            return
        # payload share of the wrench, in the platform frame: τ_p = c × f_p = -[f_p] c
        xs, xdots, xddots = np.array(shifted[:6]), np.array(shifted[6:12]), np.array(shifted[12:])
        w_p = w - kernels.platform_wrench(self.robot, xs, xdots, xddots)
        RT = rotation_matrix(xs[3:]).T
        f_p, tau_p = RT @ w_p[:3], RT @ w_p[3:]
        fx, fy, fz = f_p.tolist()
        S = np.array([[0.0, -fz, fy], [fz, 0.0, -fx], [-fy, fx, 0.0]])
        self.cog_filter.push((S.T @ S).ravel().tolist() + (-S.T @ tau_p).tolist())

    def _centre_of_gravity(self) -> np.ndarray | None:
        if self.m_c <= self.params.cog_min_mass or self.cog_filter.mean is None:
            return None
        normal = self.cog_filter.mean
        # minimum-norm solution: the right-hand side has no part along the unobservable direction
        # (the force), so a Tikhonov term far below the observable eigenvalues leaves it at zero
        N = normal[:9].reshape(3, 3)
        return np.linalg.solve(N + 1e-9 * np.trace(N) * np.eye(3), normal[9:])

    def update(self, x_d, xdot_d, xddot_d, f, x=None, ik_d=None) -> np.ndarray:
        """One period: set-point (pose, twist, acceleration), the measured forces f at the platform
        [N] and the estimated pose x -> x_d,LC (6,) [m, m, m, rad, rad, rad] as a pose offset (zero
        when disabled).

        ik_d: inverse_kinematics(robot, x_d) when the caller has it. x: see :meth:`identify`.
        """
        x_d = np.asarray(x_d, dtype=float)
        ik = ik_d
        if ik is None and (self.params.enabled or self.settlement.ratio > 0.0):
            ik = kernels.inverse_kinematics(self.robot, x_d)           # compiled: every period
        # the identification (4.4) alone (disabled) needs only A^T
        AT = kernels.inverse_kinematics_fields(self.robot, x_d, "AT")[0] if ik is None else ik.AT
        f = np.asarray(f, dtype=float)
        self.identify(x_d, xdot_d, xddot_d, f, AT, x)
        self.m_c = self.m_hat - self.m_p
        self.periods += 1
        # tared once (4.4) is in its final form: the window full and, with the estimated pose's
        # acceleration, its history of a window and h (a tare of the commanded form before would
        # leave the difference of the two as an offset)
        if (self.params.tare_at_start and not self.tared
                and self.periods >= self.wrench_filter.n + max(self._delay_n, 1)
                and (self.pose_acceleration or x is None or self.params.acceleration_source == "commanded")):
            self.tare()                                  # retried each period until not guarded
        self.cog = self._centre_of_gravity()
        f, finite = self._window_forces(f, ik)
        return self._offset(x_d, ik, f, finite)

    def _window_forces(self, f: np.ndarray, ik) -> tuple[np.ndarray, bool]:
        """(the forces of (4.4)'s window (m,) [N], whether f was finite): the window's mean, which
        also updates the unloaded reference forces, the slack count and the settlement model; f
        itself where neither the offset nor the settlement needs the mean."""
        f_floats = f.ravel().tolist()
        finite = all_finite(f_floats)
        if finite:
            f_mean = self.force_filter.push(f_floats)             # the forces of the window of (4.4)
            f_slack = self.f_slack
            self.slack_cables = sum(1 for v in f_mean if v < f_slack)
            if not self.guarded and abs(self.m_c) <= REFERENCE_FRACTION * self.m_p:
                self.f_ref = f_mean                               # an unloaded state (see secant_offset)
            if self.params.enabled or self.settlement.ratio > 0.0:
                f = np.array(f_mean)
            if self.settlement.ratio > 0.0:
                if self.settlement.f_settled is None and self.f_ref is not None:
                    self.settlement.reset(self.f_ref)             # no tare: settled to the first unloaded state
                self.settlement.update(f, cable.total_free_length(self.robot, ik.q))
        return f, finite

    def _offset(self, x_d: np.ndarray, ik, f: np.ndarray, finite: bool) -> np.ndarray:
        """x_d,LC (6,): the pose offset that cancels the compensated wrench's sag (4.5)-(4.6) at the
        window's forces f, low-passed and rate-limited (zero when disabled; the last target where f
        was not finite or the stiffness singular)."""
        p = self.params
        if not p.enabled:
            s = self.pose_settlement()
            # x_d,LC off (force control): an identified settlement is still a known length error of
            # the cables, taken out here rather than by the OSPC's integral chasing its creep
            self.x_lc = np.zeros(6) if s is None else settlement_offset(ik, s, x_d[3:])
            self.rate_limited[:] = False        # (the output filter stays at zero: set_params reset it)
            return self.x_lc.copy()
        if finite:
            try:
                cog = self.cog if p.torque else None
                w_c = compensating_wrench(self.m_c, self.robot.gravity, cog, rotation_matrix(x_d[3:]))
                if p.offset_model == "secant":
                    dx = secant_offset(self.robot, ik, f, w_c, self._reference_forces(), self.f_slack,
                                       settlement=self.settlement.s if self.settlement.ratio > 0.0 else None)
                else:
                    k_l = cable_stiffness_model(self.robot, ik, f, p.stiffness_model, self.f_slack)
                    dx = compliance(ik, f, k_l) @ w_c                                      # (4.5)-(4.6)
                target = twist_to_pose_offset(dx, x_d[3:])
                if np.all(np.isfinite(target)):
                    self.x_target = target
            except np.linalg.LinAlgError:
                pass                                      # singular K_x or K_c: keep the last target
        step = self.dt * np.repeat((p.v_max, p.omega_max), 3)
        change = self.output_filter.update(self.x_target) - self.x_lc
        self.rate_limited = np.abs(change) > step
        self.x_lc = self.x_lc + np.clip(change, -step, step)
        return self.x_lc.copy()

    @property
    def active(self) -> bool:
        """Whether the output offset acts: x_d,LC (4.6) is enabled, or the settlement is identified
        (then the output is :func:`settlement_offset` of the model's s where x_d,LC is off; x_d,LC
        holds s itself, :func:`secant_offset`)."""
        return self.params.enabled or self.pose_settlement() is not None

    def pose_settlement(self) -> np.ndarray | None:
        """The settlement s (m,) [m] for the pose estimator (section 4.1.3: the settled cables are
        longer than the encoders say, at the same forces), None unless the ratio was identified
        (``settlement_identified``) and is not zero: an assumed ratio stays out of the pose."""
        if not (self.params.settlement_identified and self.settlement.ratio > 0.0):
            return None
        return self.settlement.s.copy()

    def slack_problem(self) -> str | None:
        """Why the compensation cannot hold the payload stiffly (None while it can, or is disabled):
        cables the payload has slackened. x_d,LC is a pose offset, which cannot tension them (the
        internal forces are not in its reach), so under position control they stay slack (on the
        Mini, whose lower cables carry 5 N, under any payload worth compensating) and the force
        watch may hold the robot; force control keeps them at f_min."""
        if not self.params.enabled or not self.slack_cables:
            return None
        return (f"{self.slack_cables} of {self.robot.m} cables slack under the payload: x_d,LC cannot "
                "tension them; carry this payload under force control")

    def payload_wrench(self, x_d, xdot_d, xddot_d) -> np.ndarray:
        """The wrench of the identified payload (point mass m_c at its cog, or at the platform origin
        while the cog is not identified) for the force distribution's model wrench (2.33)."""
        cog = np.zeros(3) if self.cog is None else self.cog
        return payload_wrench(self.robot, x_d, xdot_d, xddot_d, self.m_c, cog)


class LoadCompensationStage:
    """:class:`LoadCompensation` as an offset stage of :class:`cdpr_control.control.loop.ControlLoop`
    (what the ``load_compensation`` node and the joint command do over topics). With
    ``feed_force_setpoint`` the identified payload's wrench joins the force set-point's model wrench
    (the force_distribution node's ``payload_input``)."""

    def __init__(self, robot, dt: float, params: LoadCompensationParams | None = None,
                 feed_force_setpoint: bool = False):
        self.compensation = LoadCompensation(robot, dt, params)
        self.feed_force_setpoint = feed_force_setpoint

    def offset(self, inputs):
        from cdpr_control.control.loop import OffsetOutput

        lc = self.compensation
        x = lc.update(inputs.x_d, inputs.xdot_d, inputs.xddot_d, inputs.f, inputs.x, inputs.ik_d)
        w = lc.payload_wrench(inputs.x_d, inputs.xdot_d, inputs.xddot_d) if self.feed_force_setpoint else None
        return OffsetOutput(lc.active, x, w)

    def pose_settlement(self) -> np.ndarray | None:
        """For the loop's pose estimator: :meth:`LoadCompensation.pose_settlement`."""
        return self.compensation.pose_settlement()

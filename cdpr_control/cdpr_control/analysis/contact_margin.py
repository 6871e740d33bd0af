"""Gain and phase margins of the contact force loop in state D (thesis section 5.1, (5.3)), as
:class:`cdpr_control.control.hybrid_force_control.HybridForceControl` runs it: discrete, period dt.

The loop, from the offset x_t the PID commands in period k back to it (negative feedback: the
contact force F rises with x_t and e_F = F_d - F):

    L(z) = G(z) * H_F(z) * C(z),   G(z) = k_met G_a(z) (static) or the platform's, G_a inside

* G_a(z): the drive (3.10) e^{-T_d s} / (1 + T_1 s) or (5.11) e^{-T_d s} / (1 + 2 zeta T_w s + (T_w s)^2)
  behind a zero-order hold of one period, discretised exactly, the dead time included (its whole
  periods as z^-N, the fraction by splitting the hold interval). Its one-period delay is the loop's:
  the force measured in period k + 1 is the plant's answer to the command of period k.
* H_F(z) = alpha / (1 - (1 - alpha) z^-1), alpha = 1 - e^{-dt / T_F}: the PT1 on the contact force
  (:class:`cdpr_control.control.filters.LowPass`).
* C(z) = (1 + T_d,PID (1 - z^-1) / dt) / k_pid + dt / (K_p T_i) / (1 - z^-1): (5.3)'s P part over the
  stiffness it divides by in D (``HybridForceControl.k_pid``), its D part on the filtered measurement
  (the same sign as the P part in the loop; a step of F_d does not pass it), the I part with gain
  1 / (K_p T_i) as ``HybridForceControl._pid`` integrates it (forward, x_t = P + the new integral).
* G(z), the plant: the force follows the drive's position statically with k_met, the stiffness the
  force meets (robot and surface in series along z_t, as B measures it: ``HybridForceControl.k_contact``),
  or, with a :class:`PlatformPlant`, the platform in contact: the 6-DOF platform on its cables and
  the surface, the output the contact force as the controller computes it from the cable forces.
  Above the platform's modes that force follows the winches with the cables' stiffness, many times
  k_met: the static model misses the 52 Hz oscillation of IPAnema 3 sweep pose #33 (15 dB of margin
  where the simulation grew), the platform model finds it (docs/hybrid_force_control.md, "Contact
  margin (session 14)").

The gain margin is the factor by which the whole loop gain may grow before the loop is unstable
(the phase crossings of -180 deg, the worst one); the phase margin is 180 deg plus the phase at the
gain crossover(s), the worst one. :func:`closed_loop_response` runs the same loop as difference
equations (the brute-force check of the margins, tests/control/test_contact_margin.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import expm

N_GRID = 6000               # frequencies of the Nyquist grid, log-spaced from W_MIN to pi / dt
W_MIN = 1e-2                # rad/s
STIFFEST_SURFACE = 1000.0   # a k_met at or above what the robot gives on a rigid surface: a surface this
                            # many times the robot's own stiffness at the contact point


@dataclass(frozen=True)
class DriveModel:
    """The drive's position transfer function (3.10) / (5.11): model "pt1_deadtime" (T_1) or
    "second_order" (T_w, zeta), dead time T_d [s]."""

    model: str = "pt1_deadtime"
    T_d: float = 0.0
    T_1: float = 0.0
    T_w: float = 0.0
    zeta: float = 1.0

    @classmethod
    def of(cls, drive) -> "DriveModel":
        """From a robot's drive section (``robot.drive``)."""
        return cls(str(drive.model), float(drive.T_d), float(getattr(drive, "T_1", 0.0) or 0.0),
                   float(getattr(drive, "T_w", 0.0) or 0.0), float(getattr(drive, "zeta", 1.0)))

    def state_space(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C) of the rational part (unit static gain); empty for a pure dead time."""
        if self.model == "second_order" and self.T_w > 0.0:
            w = 1.0 / self.T_w
            return (np.array([[0.0, 1.0], [-w * w, -2.0 * self.zeta * w]]), np.array([0.0, w * w]),
                    np.array([1.0, 0.0]))
        if self.model != "second_order" and self.T_1 > 0.0:
            return np.array([[-1.0 / self.T_1]]), np.array([1.0 / self.T_1]), np.array([1.0])
        return np.zeros((0, 0)), np.zeros(0), np.zeros(0)


@dataclass(frozen=True)
class PlatformPlant:
    """The platform in contact, linearised at a pose (the thesis's (2.18)-(2.22), (2.33)): what the
    contact force measured from the cable forces does when the winches move by y along z_t.

        M xddot + (D_c + d_env j j^T) xdot + (K_x + k_env j j^T) x = K_c zz y + D_c zz ydot
        F = z_t . (K_c zz y + D_c zz ydot - K_x x - D_c xdot)_F

    x = [dr; dtheta] the platform's small motion, M (2.33), K_x = K_g + K_c (2.22) at the cable
    forces f, D_c = tau_c K_c the cables' Kelvin-Voigt damping, zz = [z_t; 0] (x_t moves the set-point
    along z_t, the winches follow by A zz y), j = [z_t; r_c x z_t] the contact point r_c's direction,
    k_env and d_env the surface. F is the contact force the controller computes, the cable wrench's
    force along z_t (the weight taken out): above the platform's modes the platform stands and F
    follows the winches with the cables' stiffness, not with the stiffness met (k_met, the series of
    the robot's and the surface's): at IPAnema 3 sweep pose #33 eleven times k_met at 52 Hz."""

    M: np.ndarray
    K_x: np.ndarray
    K_c: np.ndarray
    z_t: np.ndarray
    j: np.ndarray
    k_env: float
    d_env: float
    tau_c: float

    def robot_stiffness(self) -> float:
        """The robot's stiffness [N/m] at the contact point along z_t: 1 / (j^T K_x^-1 j)."""
        return 1.0 / float(self.j @ np.linalg.solve(self.K_x, self.j))

    def static_gain(self, k_env: float | None = None) -> float:
        """F / y at rest [N/m] (with the surface k_env, default this plant's): about the robot's and
        the surface's stiffness in series, k_met (not exactly: x_t moves the platform's origin, the
        surface holds the contact point, and K_x holds the geometric stiffness that K_c lacks)."""
        k_env = self.k_env if k_env is None else k_env
        zz = np.r_[self.z_t, 0.0, 0.0, 0.0]
        Kzz = self.K_c @ zz
        x = np.linalg.solve(self.K_x + k_env * np.outer(self.j, self.j), Kzz)
        return float(zz @ (Kzz - self.K_x @ x))

    def with_drive(self, A_d, B_d, C_d) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C_k, C_r) of drive and platform: state X = [drive; x; xdot], input the drive's
        command, output F = C_k X + C_r Xdot: the cables' elastic force C_k X and their damping force,
        tau_c times the elastic force's rate (:func:`discretise` samples it as the rate over the
        period before the sample, as the simulator's implicit cable damper computes it)."""
        nd = A_d.shape[0]
        M_inv = np.linalg.inv(self.M)
        zz = np.r_[self.z_t, 0.0, 0.0, 0.0]
        P = np.r_[self.z_t, 0.0, 0.0, 0.0]
        jj = np.outer(self.j, self.j)
        D_c = self.tau_c * self.K_c
        K_tot, D_tot = self.K_x + self.k_env * jj, D_c + self.d_env * jj
        Kzz, Dzz = self.K_c @ zz, D_c @ zz
        n = nd + 12
        A, B, C_k, C_r = np.zeros((n, n)), np.zeros(n), np.zeros(n), np.zeros(n)
        A[nd:nd + 6, nd + 6:] = np.eye(6)
        A[nd + 6:, nd:nd + 6] = -M_inv @ K_tot
        A[nd + 6:, nd + 6:] = -M_inv @ D_tot
        C_k[nd:nd + 6], C_r[nd:nd + 6] = -P @ self.K_x, -P @ D_c
        if nd:
            A[:nd, :nd], B[:nd] = A_d, B_d
            A[nd + 6:, :nd] = M_inv @ (np.outer(Kzz, C_d) + np.outer(Dzz, C_d @ A_d))
            B[nd + 6:] = M_inv @ Dzz * float(C_d @ B_d)
            C_k[:nd], C_r[:nd] = (P @ Kzz) * C_d, (P @ Dzz) * C_d
        else:
            raise ValueError("the platform model needs a drive with a rational part (T_1 or T_w > 0)")
        return A, B, C_k, C_r


def platform_plant(robot, x, f, z_t, r_c, k_met: float, tau_c: float = 0.002,
                   damping_time_env: float = 0.01) -> PlatformPlant:
    """:class:`PlatformPlant` at pose x with cable forces f [N], the task axis z_t and the contact
    point r_c [m, base-frame offset from the platform's origin], from quantities the controller
    knows: the robot's geometry, cables and mass, and the stiffness met k_met [N/m] measured in B,
    from which the surface's k_env follows (the one whose static gain is k_met; a k_met at or above
    what a rigid surface gives: :data:`STIFFEST_SURFACE` times the robot's own stiffness). The
    cables' damping time tau_c (ASSUMPTION: 2 ms, the simulator's, a platform damping ratio of about
    5 %, section 3.3.2) and the surface's d_env = damping_time_env k_env (ASSUMPTION, as
    ``HPFCParams.d_env`` of the shipped files: 0.01 s) are not measured in B."""
    from cdpr_control.model import cable
    from cdpr_control.model.dynamics import mass_matrix
    from cdpr_control.model.kinematics import inverse_kinematics
    from cdpr_control.model.stiffness import cable_stiffness, geometric_stiffness

    x = np.asarray(x, dtype=float)
    f = np.asarray(f, dtype=float)
    z_t = np.asarray(z_t, dtype=float) / np.linalg.norm(z_t)
    ik = inverse_kinematics(robot, x)
    k_l = cable.tangent_stiffness(robot, f, cable.total_free_length(robot, ik.q))
    K_c = cable_stiffness(ik, k_l)
    K_x = K_c + geometric_stiffness(ik, f)
    K_x = 0.5 * (K_x + K_x.T)
    j = np.r_[z_t, np.cross(np.asarray(r_c, dtype=float), z_t)]
    plant = PlatformPlant(mass_matrix(robot, x), K_x, K_c, z_t, j, 0.0, 0.0, tau_c)
    # the surface whose static gain is k_met (rising with k_env): bisection on log k_env
    k_r = plant.robot_stiffness()
    lo, hi = math.log(1e-4 * k_r), math.log(STIFFEST_SURFACE * k_r)
    if plant.static_gain(math.exp(hi)) <= k_met:
        k_env = math.exp(hi)
    else:
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if plant.static_gain(math.exp(mid)) < k_met else (lo, mid)
        k_env = math.exp(0.5 * (lo + hi))
    return replace(plant, k_env=k_env, d_env=damping_time_env * k_env)


@dataclass(frozen=True)
class DiscreteDrive:
    """The sampled loop's plant (the drive, and the platform where given) behind the hold:
    x[k+1] = Phi x[k] + Gb u[k-N] + Ga u[k-N-1], y[k] = C x[k] + Cr (x[k] - x[k-1]) / dt (the
    platform's damping force as the rate over the period before the sample; a pure dead time
    without platform: y[k] = (1 - frac) u[k-N-1] + frac u[k-N-2]); :func:`discretise`."""

    Phi: np.ndarray
    Gb: np.ndarray
    Ga: np.ndarray
    C: np.ndarray
    N: int
    frac: float                 # the dead time's fraction of a period, delta / dt
    Cr: np.ndarray | None = None
    dt: float = 1.0

    def response(self, z: np.ndarray) -> np.ndarray:
        zi = 1.0 / z
        if self.Phi.size == 0:  # a pure dead time behind the hold
            return zi ** (self.N + 1) * ((1.0 - self.frac) + self.frac * zi)
        n = self.Phi.shape[0]
        out = np.empty(z.shape, dtype=complex)
        for i, (zz, zzi) in enumerate(zip(z, zi)):
            X = np.linalg.solve(zz * np.eye(n) - self.Phi, self.Gb + self.Ga * zzi) * zzi ** self.N
            out[i] = self.C @ X + (0.0 if self.Cr is None else (self.Cr @ X) * (1.0 - zzi) / self.dt)
        return out


def discretise(drive: DriveModel, dt: float, plant: PlatformPlant | None = None) -> DiscreteDrive:
    """The drive (and the platform, where given) behind a zero-order hold of period dt, exactly
    (dead time T_d = N dt + delta: over a period the held input is u[k-N-1] for delta, then u[k-N];
    the platform's damping force sampled as its rate over the period before the sample)."""
    N = int(math.floor(drive.T_d / dt + 1e-9))
    delta = max(0.0, drive.T_d - N * dt)
    A, B, C = drive.state_space()
    Cr = None
    if plant is not None:
        A, B, C, Cr = plant.with_drive(A, B, C)
    n = A.shape[0]
    if n == 0:
        return DiscreteDrive(np.zeros((0, 0)), np.zeros(0), np.zeros(0), np.zeros(0), N, delta / dt)

    def phi_gamma(h: float) -> tuple[np.ndarray, np.ndarray]:
        Mx = np.zeros((n + 1, n + 1))
        Mx[:n, :n], Mx[:n, n] = A * h, B * h
        E = expm(Mx)
        return E[:n, :n], E[:n, n]

    Phi, _ = phi_gamma(dt)
    Phi_rest, Gb = phi_gamma(dt - delta)
    _, G_delta = phi_gamma(delta)
    return DiscreteDrive(Phi, Gb, Phi_rest @ G_delta, C, N, delta / dt, Cr, dt)


@dataclass(frozen=True)
class ContactLoop:
    """The quantities of the loop (SI): period dt, the PID (5.3) K_p [N/m], T_i, T_d [s], the
    stiffness its P part divides by k_pid [N/m], the force filter T_F [s], the drive, the stiffness
    the force meets k_met [N/m], and the platform (:class:`PlatformPlant`; None: the force follows
    the drive statically with k_met)."""

    dt: float
    K_p: float
    T_i: float
    T_d: float
    T_F: float
    k_pid: float
    k_met: float
    drive: DriveModel
    plant: PlatformPlant | None = None

    def __post_init__(self):
        object.__setattr__(self, "_sampled", discretise(self.drive, self.dt, self.plant))

    @property
    def sampled(self) -> DiscreteDrive:
        """The plant behind the hold, x_t [m] -> the drive's position [m] (static: times k_met) or the
        measured contact force [N] (platform)."""
        return self._sampled

    def plant_gain(self) -> float:
        """The factor from the sampled plant's output to the force [N]: k_met without platform."""
        return 1.0 if self.plant is not None else self.k_met

    def alpha(self) -> float:
        return 1.0 if self.T_F <= 0.0 else 1.0 - math.exp(-self.dt / self.T_F)

    def response(self, w) -> np.ndarray:
        """L(e^{j w dt}) at the angular frequencies w [rad/s]."""
        w = np.atleast_1d(np.asarray(w, dtype=float))
        z = np.exp(1j * w * self.dt)
        zi = 1.0 / z
        a = self.alpha()
        H_F = a / (1.0 - (1.0 - a) * zi)
        C = (1.0 + self.T_d * (1.0 - zi) / self.dt) / self.k_pid + self.dt / (self.K_p * self.T_i) / (1.0 - zi)
        return self.plant_gain() * self.sampled.response(z) * H_F * C


@dataclass(frozen=True)
class Margins:
    gain: float                  # factor (inf: no phase crossing)
    phase_deg: float             # deg (inf: no gain crossover)
    w_phase: float               # rad/s, the phase crossover of the gain margin (nan: none)
    w_gain: float                # rad/s, the gain crossover of the phase margin (nan: none)

    @property
    def gain_dB(self) -> float:
        return 20.0 * math.log10(self.gain) if self.gain > 0.0 else -math.inf

    @property
    def f_phase(self) -> float:
        return self.w_phase / (2.0 * math.pi)

    def meets(self, gain_dB: float = 6.0, phase_deg: float = 45.0) -> bool:
        return self.gain_dB >= gain_dB and self.phase_deg >= phase_deg


def _refine(f, lo: float, hi: float, n: int = 60) -> float:
    """A sign change of f in [lo, hi], by bisection."""
    f_lo = f(lo)
    for _ in range(n):
        mid = 0.5 * (lo + hi)
        f_mid = f(mid)
        if (f_mid > 0.0) == (f_lo > 0.0):
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def margins(loop: ContactLoop) -> Margins:
    """Gain and phase margins of L over (0, pi / dt) (the worst phase crossing and gain crossover)."""
    w = np.geomspace(W_MIN, math.pi / loop.dt * (1.0 - 1e-9), N_GRID)
    L = loop.response(w)
    one = lambda v: complex(loop.response(v)[0])     # noqa: E731
    gain, w_pc = math.inf, math.nan
    im = L.imag
    for i in np.flatnonzero(np.sign(im[:-1]) != np.sign(im[1:])):
        wc = _refine(lambda v: one(v).imag, w[i], w[i + 1])
        Lc = one(wc)
        if Lc.real < 0.0 and 1.0 / abs(Lc) < gain:
            gain, w_pc = 1.0 / abs(Lc), wc
    # at Nyquist L is real: a negative real L there is a phase crossing too
    L_ny = complex(loop.response(math.pi / loop.dt)[0])
    if L_ny.real < 0.0 and abs(L_ny.imag) < 1e-9 * abs(L_ny) and 1.0 / abs(L_ny) < gain:
        gain, w_pc = 1.0 / abs(L_ny), math.pi / loop.dt
    phase, w_gc = math.inf, math.nan
    mag = np.abs(L) - 1.0
    for i in np.flatnonzero(np.sign(mag[:-1]) != np.sign(mag[1:])):
        wc = _refine(lambda v: abs(one(v)) - 1.0, w[i], w[i + 1])
        pm = 180.0 + math.degrees(math.atan2(one(wc).imag, one(wc).real))
        pm = (pm + 180.0) % 360.0 - 180.0
        if pm < phase:
            phase, w_gc = pm, wc
    return Margins(gain, phase, w_pc, w_gc)


def closed_loop_response(loop: ContactLoop, periods: int, scale: float = 1.0) -> np.ndarray:
    """The force F [N, per N of a step of F_d] of the closed loop, the loop gain scaled by ``scale``
    (the plant's output times scale), run as difference equations period by period, the PID as
    ``HybridForceControl._pid`` computes it (no saturation): the brute-force check of
    :func:`margins` (stable below the gain margin, growing above it)."""
    dd = loop.sampled
    a, dt = loop.alpha(), loop.dt
    n = dd.Phi.shape[0]
    xs = np.zeros(n)
    xs_prev = np.zeros(n)
    hist = [0.0] * (dd.N + 2)          # before period k's command: hist[j] = u[k - 1 - j]
    Ff, F_prev, integ = 0.0, 0.0, 0.0
    out = np.empty(periods)
    gain = scale * loop.plant_gain()
    for k in range(periods):
        # the plant's answer in this period to the commands before it
        if n:
            y = float(dd.C @ xs) + (0.0 if dd.Cr is None else float(dd.Cr @ (xs - xs_prev)) / dt)
        else:
            y = (1.0 - dd.frac) * hist[dd.N] + dd.frac * hist[dd.N + 1]       # u[k-N-1], u[k-N-2]
        F_true = gain * y
        Ff = F_true if a == 1.0 else Ff + a * (F_true - Ff)
        e_F = 1.0 - Ff
        dF = (Ff - F_prev) / dt if k else 0.0
        F_prev = Ff
        integ = integ + dt / (loop.K_p * loop.T_i) * e_F
        u = (e_F - loop.T_d * dF) / loop.k_pid + integ
        out[k] = F_true
        hist = [u] + hist[:-1]
        if n:
            xs, xs_prev = dd.Phi @ xs + dd.Gb * hist[dd.N] + dd.Ga * hist[dd.N + 1], xs
    return out


def loop_of(hpfc_params, drive, dt: float, k_met: float, k_pid: float | None = None,
            plant: PlatformPlant | None = None) -> ContactLoop:
    """The loop of a controller with parameters ``hpfc_params`` (HPFCParams), the robot's drive
    section, dt, the stiffness met k_met (B's measurement), the stiffness its P part divides by
    (default: session 14's max(K_p, k_met)) and the platform (None: static)."""
    p = hpfc_params
    if k_pid is None:
        k_pid = max(p.K_p, k_met)
    return ContactLoop(dt, p.K_p, p.T_i, p.T_d, p.T_F, k_pid, k_met, DriveModel.of(drive), plant)


def pressing_forces(robot, x, z_t, F_d: float, r_c, f_min, f_max) -> np.ndarray:
    """The cable forces [N] (m,) pressing F_d [N] along z_t at the contact point r_c [m, base-frame
    offset from the platform's origin] at pose x: the force distribution's QP (3.27)-(3.28) for the
    platform's weight plus the surface's push back, -F_d [z_t; r_c x z_t]."""
    from cdpr_control.force_distribution.methods import distribute
    from cdpr_control.model.dynamics import gravity_wrench
    from cdpr_control.model.kinematics import inverse_kinematics

    x = np.asarray(x, dtype=float)
    z_t = np.asarray(z_t, dtype=float) / np.linalg.norm(z_t)
    j = np.r_[z_t, np.cross(np.asarray(r_c, dtype=float), z_t)]
    ik = inverse_kinematics(robot, x)
    return distribute(ik.AT, gravity_wrench(robot, x) - F_d * j, f_min, f_max).f


def case_margins(robot, hpfc_params, dt: float, x, z_t, F_d: float, r_c, k_met: float, k_pid: float,
                 f_min, f_max, drive=None) -> Margins:
    """The margins of the contact loop at a contact case: pose x, task axis z_t, force F_d, contact
    point r_c, the stiffness met k_met and the P part's k_pid; the platform at the distribution's
    pressing forces (:func:`pressing_forces`); ``drive`` (default the robot's) e.g. a plant's own."""
    f = pressing_forces(robot, x, z_t, F_d, r_c, f_min, f_max)
    plant = platform_plant(robot, x, f, z_t, r_c, k_met)
    return margins(loop_of(hpfc_params, robot.drive if drive is None else drive, dt, k_met, k_pid, plant))

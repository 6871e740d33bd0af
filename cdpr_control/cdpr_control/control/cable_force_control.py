"""Joint-space cable force control (CFC), thesis section 3.5.2, Fig. 3.12.

Per cable: the measured force f is low-pass filtered (3.20), the error e_f = f_d - f (3.2) drives
a PI controller (3.19) with saturation F_sat,n / F_sat,p and anti-windup, the feed-forward
f_ff = f_d (3.22) is added, and the controller output f_c,out becomes a cable length through the
linear stiffness estimate K_l = k_spec / l_t (2.15), minus the pre-tension Δq_0 (3.23):

    Δq_CFC = K_l^-1(l_t) f_c,out - Δq_0 .

Δq_CFC is the elongation commanded beyond the encoder calibration's pre-tension; the joint command
shortens the winch by it (θ_d = q_d - Δq_CFC, see :mod:`cdpr_control.control.joint_command`).

Near the force limits the saturation is widened (section 3.5.2): a cable close to f_min (sagging,
much softer than modelled) may pull harder, a cable close to f_max may release harder.

With ``internal_integral`` (off by default, on in the IPAnema 3's parameter file; a departure from the
printed (3.19): docs/load_compensation.md, "The CFC's integral part on the internal forces") the
integral part integrates only the internal
forces, the component of the force error in the nullspace of A^T(x_d) (2.41)
(:func:`internal_pi_update`): a force change in that nullspace moves no pose, so the pose is the
OSPC's (3.16) alone and the integral part leaves no pose offset after a payload step
(docs/validation.md, "Payload after session 11", cause B). Not under hybrid force control in
contact (section 5.1.2: its integral part along the contact is handed over to x_t).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdpr_control.model import cable
from cdpr_control import kernels
from cdpr_control.model.calibration import DEFAULT_WINDOW, StartupCalibration
from cdpr_control.model.memo import Memo
from cdpr_control.control.bumpless import START_FORCE_RANGE_TIME
from cdpr_control.control.filters import LowPass
from cdpr_control.control.pi_control import PIController, pi_update
from cdpr_control.kernels import cfc_constants


@dataclass
class CFCParams:
    """Parameters of the cable force controller (defaults: table 3.1 where given)."""

    K_p: float = 0.85            # -, proportional gain, table 3.1
    T_i: float = 0.1             # s, integrator reset time, table 3.1
    T_filter: float = 0.08       # s, PT1 of the force feedback (3.20), table 3.1 (T_1,r)
    F_sat_n: float = 200.0       # N, negative saturation of the PI part (ASSUMPTION per robot)
    F_sat_p: float = 200.0       # N, positive saturation of the PI part (ASSUMPTION per robot)
    widen_band: float = 50.0     # N, distance to a force limit where widening starts
    widen_factor: float = 3.0    # -, saturation multiplier reached at the limit
    stiffness_model: str = "nonlinear"   # K_l of (3.23): "linear" (thesis, (2.15)) or "nonlinear" (2.17)
    # the integral part of (3.19) integrates only the internal forces (the nullspace of A^T(x_d),
    # (2.41)), where the caller gives x_d: internal_pi_update; False: the printed (3.19)
    internal_integral: bool = False

    def validate(self) -> None:
        checks = {
            "K_p": self.K_p >= 0.0,
            "T_i": self.T_i > 0.0,
            "T_filter": self.T_filter >= 0.0,
            "F_sat_n": self.F_sat_n >= 0.0,
            "F_sat_p": self.F_sat_p >= 0.0,
            "widen_band": self.widen_band > 0.0,
            "widen_factor": self.widen_factor >= 1.0,
            "stiffness_model": self.stiffness_model in ("linear", "nonlinear"),
            "internal_integral": isinstance(self.internal_integral, (bool, np.bool_)),
        }
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"invalid CFC parameters: {', '.join(f'{k}={getattr(self, k)}' for k in bad)}")


def _widened(f, f_min, f_max, F_sat_n, F_sat_p, band, factor) -> tuple[np.ndarray, np.ndarray]:
    """Saturation magnitudes (F_sat,n, F_sat,p) raised linearly up to ``factor`` times as f enters
    the band of width ``band`` at f_max and f_min (section 3.5.2)."""
    near_min = np.clip((f_min + band - f) / band, 0.0, 1.0)
    near_max = np.clip((f - (f_max - band)) / band, 0.0, 1.0)
    gain = factor - 1.0
    return F_sat_n * (1.0 + gain * near_max), F_sat_p * (1.0 + gain * near_min)


def _widened_saturation(params: CFCParams, f, f_min, f_max) -> tuple[np.ndarray, np.ndarray]:
    return _widened(f, f_min, f_max, params.F_sat_n, params.F_sat_p, params.widen_band, params.widen_factor)


widened_saturation = kernels.law("widened_saturation", _widened_saturation, kernels.compiled_widened_saturation)


def _cfc_period(f_d, f_ff, f, f_min, f_max, l_t, dq_0, y, integrator, K_p, T_i, constants):
    """One period of the cable force controller (3.19)-(3.23) on arrays -> new arrays (integrator,
    saturated, u, f_c,out, Δq_CFC); the PT1 state y of (3.20) is updated in place. ``constants``: the
    kernels.CFC_CONSTANTS record (PT1 alpha, dt, saturation, stiffness model); K_l is k_spec nominal /
    l_t (2.15) or the secant k_spec(f_c,out) / l_t (2.16)-(2.17)."""
    c = constants[0]
    y += c["alpha"] * (f - y)                                           # (3.20), as LowPass.update
    e = f_d - y                                                         # (3.2)
    sat_n, sat_p = _widened(y, f_min, f_max, c["F_sat_n"], c["F_sat_p"], c["widen_band"], c["widen_factor"])
    integrator, saturated, u = pi_update.reference(e, K_p, T_i, c["dt"], integrator, sat_n, sat_p)   # (3.19)
    f_out, dq = _cfc_output(f_ff, u, l_t, dq_0, c)
    return integrator, saturated, u, f_out, dq


def _cfc_output(f_ff, u, l_t, dq_0, c):
    """(f_c,out, Δq_CFC) of a CFC period: the feed-forward plus the PI output, as an elongation."""
    f_out = f_ff + u                                                    # (3.22)
    if c["linear"]:
        k = c["k_spec_nominal"] / l_t                                   # (2.15)
    else:
        k = cable.k_spec(np.maximum(f_out, 0.0), c["k0"], c["k1"], c["k2"]) / l_t   # (2.16)-(2.17)
    return f_out, f_out / k - dq_0                                      # (3.23)


cfc_period = kernels.law("cfc_period", _cfc_period, kernels.compiled_cfc_period)


def _nullspace_projector(AT, held=None) -> np.ndarray:
    """P (m, m): the orthogonal projector onto the nullspace of A^T (2.41), the cable forces that
    exert no wrench on the platform (internal forces, which move no pose); ``held`` (m,) bool: the
    cables whose component must in addition be zero (P projects onto the nullspace of [A^T; E_held^T])."""
    M = np.asarray(AT, dtype=float)
    m = M.shape[1]
    if held is not None and np.any(held):
        M = np.vstack([M, np.eye(m)[np.asarray(held, dtype=bool)]])
    else:
        # A^T of full row rank (a pose of the workspace): I - A (A^T A)^-1 A^T by a 6x6 solve, the
        # same projector as the pseudo-inverse's at a third of its cost (every period while x_d moves)
        try:
            P = np.eye(m) - M.T @ np.linalg.solve(M @ M.T, M)
            if np.abs(M @ P).max() <= 1e-9 * np.abs(M).max():      # (not where A^T is near rank-deficient)
                return P
        except np.linalg.LinAlgError:
            pass                                                     # singular: the pseudo-inverse
    return np.eye(m) - np.linalg.pinv(M) @ M


def _internal_pi_update(e, K_p, T_i, dt, integrator, u_neg, u_pos, AT):
    """One period of the PI (3.19) whose integral part integrates only internal forces -> new arrays
    (integrator, saturated, output), as :func:`cdpr_control.control.pi_control.pi_update`.

    ``u = clip(K_p e + I, -u_neg, u_pos)``; the integrator's increment is the nullspace part
    P (K_p dt / T_i e) of the printed one (P of :func:`nullspace_projector`, A^T = ``AT`` of the
    set-point x_d), so A^T I stays 0: the integral part exerts no wrench and moves no pose. The
    proportional part acts on the whole error. Anti-windup as the PI's, inside the projection:

    - conditional integration: a cable whose output is saturated and whose increment would push it
      further out is held (its increment 0), and the increment is projected again with that cable
      held (onto the nullspace of [A^T; e_i^T]) until no held cable is pushed out;
    - clamping: where the integral part alone leaves the output range, the integrator is scaled
      towards 0 (all cables by one factor, which keeps it internal) into the range.

    A part of I outside the nullspace (the integrator of the printed (3.19) when the projection
    starts, after a contact, or as x_d and with it A^T move) decays with T_i: a factor
    min(1, dt/T_i) of it per period, so the drive command does not step. The projector of ``AT`` is
    kept while A^T's bytes repeat, as at rest.

    The law :data:`internal_pi_update` runs it compiled (``kernels.compiled_internal_pi_update``, the
    projector of A^T by Gram-Schmidt on its rows over the free cables, the same numbers to rounding;
    :data:`cfc_internal_period` the whole CFC period with it)."""
    e = np.asarray(e, dtype=float)
    lo, hi = -np.asarray(u_neg, dtype=float), np.asarray(u_pos, dtype=float)
    P = _projector(AT)
    integrator = np.asarray(integrator, dtype=float)
    integrator = integrator - np.minimum(1.0, dt / T_i) * (integrator - P @ integrator)
    p = K_p * e
    printed = K_p * dt / T_i * e
    step = P @ printed
    held = None
    for _ in range(e.size):
        u_free = p + integrator + step
        pushed = ((u_free > hi) & (step > 0.0)) | ((u_free < lo) & (step < 0.0))
        if held is not None:
            pushed |= held
            if np.array_equal(pushed, held):
                break
        elif not pushed.any():
            break
        held = pushed
        step = _nullspace_projector(AT, held) @ printed
    candidate = integrator + step
    if np.any(candidate > hi) or np.any(candidate < lo):
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(candidate > hi, hi / candidate, np.where(candidate < lo, lo / candidate, 1.0))
        candidate = candidate * min(1.0, float(np.min(room)))
    integrator = candidate
    u = p + integrator
    return integrator, (u > hi) | (u < lo), np.clip(u, lo, hi)


nullspace_projector = kernels.law("nullspace_projector", _nullspace_projector, kernels.compiled_nullspace_projector)
internal_pi_update = kernels.law("internal_pi_update", _internal_pi_update, kernels.compiled_internal_pi_update)

# the reference's projector of the last A^T (x_d repeats while the robot holds a pose)
_projectors = Memo(read_only=True)


def _projector(AT) -> np.ndarray:
    AT = np.asarray(AT, dtype=float)
    return _projectors((AT.shape, AT.tobytes()), _nullspace_projector, AT)


def _cfc_internal_period(f_d, f_ff, f, f_min, f_max, l_t, dq_0, y, integrator, K_p, T_i, AT, constants):
    """:func:`cfc_period` with the internal integral: the PI (3.19) of :func:`internal_pi_update`
    with A^T = ``AT`` (6, m) of x_d (2.10), the rest of the period (3.20), (3.22)-(3.23) as there."""
    c = constants[0]
    y += c["alpha"] * (f - y)                                           # (3.20), as LowPass.update
    e = f_d - y                                                         # (3.2)
    sat_n, sat_p = _widened(y, f_min, f_max, c["F_sat_n"], c["F_sat_p"], c["widen_band"], c["widen_factor"])
    integrator, saturated, u = _internal_pi_update(e, K_p, T_i, c["dt"], integrator, sat_n, sat_p, AT)   # (3.19)
    f_out, dq = _cfc_output(f_ff, u, l_t, dq_0, c)
    return integrator, saturated, u, f_out, dq


cfc_internal_period = kernels.law("cfc_internal_period", _cfc_internal_period, kernels.compiled_cfc_internal_period)


class CableForceController:
    """Per-cable PI with feed-forward, widened saturation, anti-windup and pre-tension (3.19)-(3.23)."""

    def __init__(self, m: int, params: CFCParams, dt: float):
        params.validate()
        self.m = m
        self.params = params
        self.dt = dt
        self.pi = PIController(m, params.K_p, params.T_i, params.F_sat_n, params.F_sat_p, dt)
        self.dq_0: np.ndarray | None = None       # set by reset() before the first update
        self.feedback_filter = LowPass(params.T_filter, dt)      # (3.20)
        self.f_out = np.zeros(m)
        self.dq_cfc = np.zeros(m)
        self._f_ref: np.ndarray | None = None    # the start ramp's set-point, None once it has caught up

    def set_params(self, params: CFCParams) -> None:
        """Apply new parameters live; the integrator state is kept."""
        params.validate()
        self.params = params
        self.pi.set_gains(params.K_p, params.T_i)
        self.pi.set_limits(params.F_sat_n, params.F_sat_p)
        self.feedback_filter.set_time_constant(params.T_filter)

    def reset(self, dq_0, f=None, ramp: bool = False) -> None:
        """Start (or restart) with the pre-tension elongation Δq_0 [m] of the encoder calibration.

        ``ramp`` with the measured forces f: the start ramp (docs/control.md). The set-point f_d (and
        f_ff) rises from f to the one given at most at (f_max - f_min) per
        :data:`cdpr_control.control.bumpless.START_FORCE_RANGE_TIME` per cable, until it has caught up:
        with the full f_d from the first period the integrator wound up while the drives had not yet
        followed, and the forces overshot by 8 N at a Mini border pose (f_d 39 N, f_max 40 N)."""
        self.dq_0 = np.asarray(dq_0, dtype=float).copy()
        self.pi.reset()
        self.feedback_filter.reset(f)
        self._f_ref = np.asarray(f, dtype=float).copy() if ramp and f is not None else None

    def _set_point(self, f_d, f_ff, f_min, f_max):
        """(f_d, f_ff) of this period: during the start ramp the rate-limited set-point, f_ff shifted
        by the same lag."""
        f_ref = self._f_ref
        if f_ref is None:
            return f_d, f_ff
        step = (np.asarray(f_max, dtype=float) - f_min) * (self.dt / START_FORCE_RANGE_TIME)
        lag = f_d - f_ref
        if np.all(np.abs(lag) <= step):
            self._f_ref = None                   # caught up: f_d from now on
            return f_d, f_ff
        self._f_ref = f_ref = f_ref + np.clip(lag, -step, step)
        return f_ref, None if f_ff is None else f_ff - (f_d - f_ref)

    @property
    def f_filtered(self) -> np.ndarray | None:
        return self.feedback_filter.y

    def filter(self, f: np.ndarray) -> np.ndarray:
        """PT1 feedback filter (3.20)."""
        return self.feedback_filter.update(f)

    def update(self, f_d, f, k_l, f_min, f_max, f_ff=None, AT=None) -> np.ndarray:
        """One period: desired and measured forces [N], cable stiffness K_l [N/m] -> Δq_CFC [m].

        k_l is the secant stiffness per cable, an array (the thesis' linear model) or a function of
        the output force f_c,out (a non-linear model (2.17): then K_l^-1 f_c,out is the elongation).
        f_ff: a feed-forward (3.22) other than f_d (hybrid force control, section 5.1.2); None: f_d.
        AT: A^T(x_d) (6, m) (2.10): the integral part integrates only internal forces
        (:func:`internal_pi_update`; not while the PI is held); None: the printed (3.19).
        """
        if self.dq_0 is None:
            raise RuntimeError("CableForceController.update before reset(dq_0)")
        f_d, f_ff = self._set_point(f_d, f_ff, f_min, f_max)
        f_fb = self.filter(f)
        e_f = f_d - f_fb                                            # (3.2)
        sat_n, sat_p = widened_saturation(self.params, f_fb, f_min, f_max)
        pi = self.pi
        if AT is None or pi.hold:
            u = pi.update(e_f, sat_n, sat_p)                        # (3.19) with saturation
        else:                                                       # (3.19), its integral internal
            pi.integrator, pi.saturated, pi.output = internal_pi_update(e_f, pi.K_p, pi.T_i, pi.dt, pi.integrator,
                                                                        sat_n, sat_p, AT)
            u = pi.output
        self.f_out = (f_d if f_ff is None else f_ff) + u            # feed-forward (3.22)
        stiffness = k_l(self.f_out) if callable(k_l) else k_l
        self.dq_cfc = self.f_out / stiffness - self.dq_0            # (3.23)
        return self.dq_cfc


    def constants(self, cable_params) -> np.ndarray:
        """The CFC_CONSTANTS record of these parameters with the stiffness model of ``cable_params``
        (the robot's cable)."""
        p = self.params
        return cfc_constants(alpha=self.feedback_filter.alpha, dt=self.pi.dt, F_sat_n=p.F_sat_n, F_sat_p=p.F_sat_p,
                             widen_band=p.widen_band, widen_factor=p.widen_factor,
                             linear=float(p.stiffness_model == "linear"), k_spec_nominal=cable_params.k_spec_nominal,
                             k0=cable_params.k0, k1=cable_params.k1, k2=cable_params.k2)

    def update_period(self, f_d, f, l_t, constants, f_min, f_max, f_ff=None, AT=None) -> np.ndarray:
        """:meth:`update` as one call of the law :func:`cfc_period` (the same arithmetic; compiled
        where the kernels are), once the feedback filter has its first sample and while the PI
        integrates (not held); ``constants`` (:meth:`constants`) instead of K_l. With ``AT`` (A^T of
        x_d) the law :func:`cfc_internal_period`: the integral part on the internal forces."""
        pi = self.pi
        f_d, f_ff = self._set_point(f_d, f_ff, f_min, f_max)
        args = (f_d, f_d if f_ff is None else f_ff, f, f_min, f_max, l_t, self.dq_0, self.feedback_filter.y,
                pi.integrator, pi.K_p, pi.T_i)
        pi.integrator, pi.saturated, pi.output, self.f_out, self.dq_cfc = (
            cfc_period(*args, constants) if AT is None else cfc_internal_period(*args, AT, constants))
        return self.dq_cfc


class CableForceControl:
    """The CFC stage of the control loop for one robot: the controller plus its stiffness model.

    K_l of (3.23) is the thesis' linear k_spec / l_t (2.15), or (default) the secant of the robot
    file's non-linear cable (2.16)-(2.17), so that K_l^-1 f_c,out is the elongation the cable
    really needs; with the linear model the integrator must make up the difference, which on the
    IPAnema 3's progressive 6 mm cable exceeds a few hundred newtons of saturation range. Δq_0 is
    the elongation of the encoder calibration's forces (:mod:`cdpr_control.model.calibration`: the home
    calibration, else the mean of the first samples) in the same model, so that f = f_d commands
    no change. Disabled, the output is zero (IK-only control).
    """

    def __init__(self, robot, dt: float, params: CFCParams | None = None, enabled: bool = True,
                 calibration_window: int = DEFAULT_WINDOW, start_ramp: bool = False):
        self.robot = robot
        self.start_ramp = start_ramp      # the set-point's start ramp (CableForceController.reset)
        self.controller = CableForceController(robot.m, params or CFCParams(), dt)
        self._constants = self.controller.constants(robot.cable)     # of the period: set with the parameters
        self.enabled = enabled
        self.calibration = StartupCalibration(calibration_window)

    @property
    def params(self) -> CFCParams:
        return self.controller.params

    def set_params(self, params: CFCParams, enabled: bool | None = None) -> None:
        model_changed = params.stiffness_model != self.params.stiffness_model
        self.controller.set_params(params)
        self._constants = self.controller.constants(self.robot.cable)
        if model_changed and self.calibration.f_0 is not None:
            self.controller.dq_0 = self._calibrated_dq_0()
        if enabled is not None and enabled != self.enabled:
            self.enabled = enabled
            self.controller.pi.reset()           # bumpless: the integrator starts from zero

    def _stiffness(self, l_t):
        if self.params.stiffness_model == "linear":
            return self.robot.cable.k_spec_nominal / l_t                       # (2.15)
        return lambda f_out: kernels.cable_stiffness(self.robot, np.maximum(f_out, 0.0), l_t)   # (2.17)

    def stiffness(self, f, theta) -> np.ndarray:
        """K_l (m,) [N/m] of (3.23) at the cable forces f [N] and encoder lengths θ [m]: the model the
        controller commands elongations with ((2.15), or the secant of (2.17) at f)."""
        l_t = cable.total_free_length(self.robot, theta)                      # (2.14)
        k_l = self._stiffness(l_t)
        return np.asarray(k_l(np.asarray(f, dtype=float)) if callable(k_l) else k_l, dtype=float) * np.ones(self.robot.m)

    def _elongation(self, f, l_t) -> np.ndarray:
        k_l = self._stiffness(l_t)
        return f / (k_l(f) if callable(k_l) else k_l)

    def _calibrated_dq_0(self) -> np.ndarray:
        c = self.calibration
        return self._elongation(c.f_0, cable.total_free_length(self.robot, c.theta_0))

    def update(self, f_d, f, theta, f_min, f_max, f_ff=None, x_d=None) -> np.ndarray:
        """Desired and measured forces [N], encoder lengths θ [m] -> Δq_CFC [m] (3.23); f_ff a
        feed-forward other than f_d (see :meth:`CableForceController.update`); x_d (6,) the
        set-point, whose A^T (2.10) confines the integral part to the internal forces where
        ``internal_integral`` is on (None: the printed (3.19))."""
        if not self.enabled:
            return np.zeros(self.robot.m)
        l_t = cable.total_free_length(self.robot, theta)                      # (2.14)
        c = self.controller
        if self.calibration.update(f, theta) or c.dq_0 is None:
            if c.dq_0 is None:                    # the start ramp once, at the first reset
                c.reset(self._calibrated_dq_0(), f=f, ramp=self.start_ramp and c.feedback_filter.y is None)
            else:
                c.dq_0 = self._calibrated_dq_0()          # the start-up window's running mean
        AT = None
        if x_d is not None and self.params.internal_integral:
            AT, = kernels.inverse_kinematics_fields(self.robot, x_d, "AT")       # (2.10) at x_d
        if c.feedback_filter.y is not None and not c.pi.hold:
            return c.update_period(f_d, f, l_t, self._constants, f_min, f_max, f_ff, AT)
        return c.update(f_d, f, self._stiffness(l_t), f_min, f_max, f_ff, AT)

"""Cable force set-point stage, thesis section 3.6: wrench set-point (3.26) then f_d (3.27)-(3.28).

Per period: the model wrench w_dyn of the desired motion (2.33); the measured wrench w enters
through the Smith predictor (3.26), whose disturbance part w - w_dyn(t - T_d,w) is low-pass filtered
(``T_wrench_filter``) and saturated (section 3.6.1): the filter acts on the disturbance only, so the
anticipated inertia wrench reaches w_d without the filter's lag; the distribution is solved for A^T at x_d with the tension level's reference force. A change
of the tension level is ramped (``tension_rate``, full range per second) so that the internal forces
move smoothly and the platform does not.

A known payload (``w_model``, the identified payload of the load compensation) is fed forward:
w_d = w_dyn + sat(PT1(w - w_ff - w_dyn(t - T_d,w))) + w_ff, w_ff = PT1_ff(w_model), so the
disturbance filter sees only what the identification has not explained and the payload reaches
f_d at the pace of the identification, not of the disturbance filter (on the Mini the lagging f_d
let the lower cables go slack while a payload was put down). Both filters keep the
measured-wrench loop w -> PT1 -> w_d -> f_d -> cable forces -> w where it was measured stable
(:func:`loop_filter_times`): the loop passes the platform's inertia through the filter, and what
decides it is ω_n T, the platform's vertical eigenfrequency (4.8) against the filter's time
constant; a payload lowers ω_n (the 90 kg divergence of docs/load_compensation.md: 2.38 Hz,
ω_n T = 4.5 with the 0.3 s filter; stable with 0.6 s, ω_n T = 9). Both time constants are
therefore at least OMEGA_T / ω_n, the disturbance filter's never below ``T_wrench_filter``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import daqp
import numpy as np

from cdpr_control import kernels
from cdpr_control.control.filters import LowPass
from cdpr_control.model import cable
from cdpr_control.model.memo import Memo
from cdpr_control.model.stiffness import cable_stiffness, geometric_stiffness
from cdpr_control.control.hybrid_force_control import FORCE_CONTROLLED, expected_contact_wrench_of, task_axis
from cdpr_control.control.load_compensation import payload_kinematics, payload_wrench_of_mass
from cdpr_control.control.safety import all_finite
from cdpr_control.force_distribution import (BACKENDS, METHODS, BorderPolicy, DistributionResult,
    ForceDistributor, Status)
from cdpr_control.control.wrench_setpoint import WrenchSetpoint


OMEGA_T = 9.0          # -, ω_n T of the measured-wrench loop: 90 kg at [-1.8, 1.2, 1.0] m on the IPAnema 3
                       # (f_n 2.38 Hz) grew with T 0.3 s (ω_n T 4.5) and held with 0.6 s (9.0)
# s: the hand's reserve from the force limits decays with this after the hand lets go (the platform's cable
# modes ring out within about 0.1 s, the measured-wrench filter T_wrench_filter has learnt the
# release after a few of its 0.3 s); below RESERVE_FLOOR [N] it is dropped
RESERVE_RELEASE_TIME = 0.5
RESERVE_FLOOR = 1e-3
RESERVE_SHARE = 0.7    # -, of the largest margin a pose leaves (:func:`largest_margin`): the rest is the QP's freedom
# -, the hand's reserve per N of its share max |Δf_i|. A hand that lets go at once is a step of -Δf on
# the lightly damped cable mode, whose response swings up to twice the step; measured on the Mini
# (session 11, grid pose #28, 13 N released): 1.35 x the share below the set-point, so 2 keeps the
# Mini's #12 and #28 above f_min after the release. (At the merge of session 11 it went back to 1:
# the IPAnema 3's eigenfrequency runs at #12 and #29 oscillated at 13 Hz until the force watch held.
# The cause was the rate of the forces the reserve adds, not the factor: _with_reserve, session 12.)
RESERVE_RING = 2.0
_INF = 1e30            # DAQP's "no bound"
EIGEN_PERIODS = 50     # periods between two evaluations of ω_n while a payload is known


def total_mass_ratio(w_dyn, w_model) -> float:
    """(m_p + m_c) / m_p read from the model wrenches: |w_dyn + w_model| / |w_dyn| of the force parts
    (both the weight less the inertia force at the same acceleration, (2.33)), at least 1 (a negative
    estimate counts as none); 1 where the platform's own force part vanishes (falling at g)."""
    own = float(np.linalg.norm(np.asarray(w_dyn, dtype=float)[:3]))
    total = float(np.linalg.norm(np.asarray(w_dyn, dtype=float)[:3] + np.asarray(w_model, dtype=float)[:3]))
    if not own > 1e-9 or not np.isfinite(total):
        return 1.0
    return max(total / own, 1.0)


def vertical_eigenfrequency(robot, x, f, mass: float) -> float:
    """ω_n [rad/s] of the platform's vertical translation at pose x with the cable forces f (m,) [N]
    and the total mass [kg]: sqrt(K_x,zz / mass), K_x = K_g + K_c (2.22) with the tangent cable
    stiffness (2.20), the diagonal approximation of (4.8) that `cdpr analyze stability` uses."""
    ik = kernels.inverse_kinematics(robot, np.asarray(x, dtype=float))
    k_l = cable.tangent_stiffness(robot, f, cable.total_free_length(robot, ik.q))
    K_zz = float((geometric_stiffness(ik, f) + cable_stiffness(ik, k_l))[2, 2])
    return float(np.sqrt(K_zz / mass)) if K_zz > 0.0 and mass > 0.0 else float("nan")


def largest_margin(AT, w, f_min, f_max) -> float:
    """The largest t [N] for which f_min + t <= f <= f_max - t, A^T f = -w has a solution (an LP,
    DAQP), at most (f_max - f_min) / 2; -inf where the wrench w is not feasible at all. One cold
    solve of :class:`MarginLP`, which the force set-point keeps warm from period to period."""
    n, m = np.shape(AT)
    return MarginLP(n, m).solve(AT, w, f_min, f_max)


class MarginLP:
    """:func:`largest_margin` as one DAQP model kept between calls: the constraint matrix and the
    bounds are allocated once, a call writes A^T and w into them and solves from the last working
    set (the pose and the user's wrench change little from one period to the next). Building the
    LP anew each period cost about 100 us of the 1 kHz loop, mostly in numpy's concatenations.

    Variables [f (m), t]; rows A^T f = -w (n), f - t >= f_min (m), f + t <= f_max (m)."""

    def __init__(self, n: int, m: int):
        self.n, self.m = n, m
        A = np.zeros((n + 2 * m, m + 1))
        A[n:n + m, :m] = A[n + m:, :m] = np.eye(m)
        A[n:n + m, m] = -1.0
        A[n + m:, m] = 1.0
        self.A = A
        self.bu = np.full(n + 3 * m + 1, _INF)               # [f, t] bounds, then the rows
        self.bl = np.full(n + 3 * m + 1, -_INF)
        self.bl[m] = 0.0
        self.sense = np.zeros(n + 3 * m + 1, dtype=np.int32)
        self.sense[m + 1:m + 1 + n] = 5                      # the equality rows A^T f = -w
        self.cost = np.r_[np.zeros(m), -1.0]                 # max t
        self.no_hessian = np.zeros((m + 1, m + 1))           # an LP (Model.setup takes no None)
        self.model = None

    def solve(self, AT, w, f_min, f_max) -> float:
        n, m = self.n, self.m
        self.A[:n, :m] = AT
        bu, bl = self.bu, self.bl
        bu[m] = float(np.min(f_max - f_min)) / 2.0
        np.negative(w, out=bu[m + 1:m + 1 + n])
        bl[m + 1:m + 1 + n] = bu[m + 1:m + 1 + n]
        bl[m + 1 + n:m + 1 + n + m] = f_min
        bu[m + 1 + n + m:] = f_max
        if self.model is None:
            self.model = daqp.Model()
            self.model.setup(self.no_hessian, self.cost, self.A, bu, bl, self.sense)
        else:
            self.model.update(A=self.A, bupper=bu, blower=bl)
        x, _, exitflag, _ = self.model.solve()
        if exitflag != 1 or not np.isfinite(x[m]):
            self.model = None                                # a failed working set is no warm start
            return -np.inf
        return float(x[m])


def user_forces(AT, w_user) -> np.ndarray:
    """Δf = (A^T)^+ w_user (m,) [N], the least-norm cable forces of the user's wrench, as
    A (A^T A)^-1 w_user with the 6 x 6 A^T A: the least-squares solution where A^T has full rank
    (everywhere in the workspace) at about half the cost of ``lstsq``; a singular A^T A falls back to it."""
    try:
        return AT.T @ np.linalg.solve(AT @ AT.T, w_user)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(AT, w_user, rcond=None)[0]


def loop_filter_times(T: float, omega_n: float) -> tuple[float, float]:
    """(disturbance filter, payload feed-forward filter) time constants [s] for the vertical mode
    ω_n [rad/s]: OMEGA_T / ω_n each, the disturbance filter at least T; where ω_n is not known
    (no tensed cable stiffens z), T for both."""
    if not (np.isfinite(omega_n) and omega_n > 0.0):
        return T, T
    T_loop = OMEGA_T / omega_n
    return max(T, T_loop), T_loop


@dataclass
class ForceSetpointParams:
    method: str = "qp"
    backend: str = "daqp"
    tension_level: float = 0.0            # [0..1]: f_ref = f_min + level (f_max - f_min) (3.27)
    tension_rate: float = 1.0             # 1/s, ramp of the tension level (0 = step)
    f_min: np.ndarray | None = None       # (m,) N, None: robot file
    f_max: np.ndarray | None = None       # (m,) N, None: robot file
    overload_factor: float = 1.0          # f_max may rise to this multiple at the border (3.6.2)
    overload_rate: float = 0.0            # 1/s, rate of the raise; 0 = instant
    wrench_source: str = "measured"       # measured: (3.26); model: w_d = w_dyn (3.1)
    T_d_w: float = 0.01                   # s, Smith predictor delay (3.25)
    wrench_deviation_max: float = 3.0     # saturation of w - w_dyn(t - T_d,w) relative to m g (payloads up to 3 m_p)
    T_wrench_filter: float = 0.3          # s, PT1 on the disturbance w - w_dyn(t - T_d,w) (0.08 s oscillates on IPAnema 3)

    def validate(self, m: int) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(sorted(METHODS))}, got {self.method!r}")
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {self.backend!r}")
        if self.wrench_source not in ("measured", "model"):
            raise ValueError(f"wrench_source must be measured or model, got {self.wrench_source!r}")
        if not 0.0 <= self.tension_level <= 1.0:
            raise ValueError(f"tension_level must be in [0, 1], got {self.tension_level}")
        for name in ("tension_rate", "overload_rate", "T_d_w", "wrench_deviation_max", "T_wrench_filter"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("f_min", "f_max"):
            value = getattr(self, name)
            if value is not None and (np.shape(value) != (m,) or not np.all(np.isfinite(value))):
                raise ValueError(f"{name} needs {m} finite values")
        BorderPolicy(overload_factor=self.overload_factor).validate()


class ForceSetpoint:
    def __init__(self, robot, dt: float, params: ForceSetpointParams | None = None):
        self.robot = robot
        self.dt = dt
        self.distributor: ForceDistributor | None = None
        self.smith = WrenchSetpoint(0.01, dt)
        self.wrench_filter = LowPass(0.08, dt)
        self.payload_filter = LowPass(0.0, dt)   # w_ff of the known payload (module doc)
        self.w_ff = np.zeros(6)
        self._eigen_in = 0                        # periods until ω_n is evaluated again
        self.f_d: np.ndarray | None = None        # the last distribution's forces (for ω_n)
        self.level: float | None = None          # tension level in effect (ramping to the target)
        self.f_ref_override: np.ndarray | None = None
        self.w_d: np.ndarray | None = None
        self.w_user: np.ndarray | None = None    # hand guiding: the user's wrench w_Adm (set_user_wrench)
        self.reserve = 0.0                       # N, the hand's reserve from f_min and f_max (_hand_reserve)
        self.reserve_applied = 0.0               # N, the reserve the last set-point kept (_with_reserve)
        self.reserve_forces = np.zeros(robot.m)  # N, what it added to the plain distribution's forces then
        self.margin_lp = MarginLP(6, robot.m)    # largest_margin, warm from period to period (_with_reserve)
        self._payload_memo = Memo()              # R c, g - a_c of the set-point's and cog's bytes (payload_wrench)
        self.z_t = np.array([0.0, 0.0, 1.0])     # task z axis of the hybrid force controller, kept in R
        self._task_axis = Memo()                 # z_t of F_d,0's bytes (_contact_wrench)
        self.set_params(params or ForceSetpointParams())
        kernels.warm_up(robot)               # the compiled w_dyn loaded now, not in the first period

    def set_params(self, p: ForceSetpointParams) -> None:
        p.validate(self.robot.m)
        c = self.robot.cable
        f_min = c.f_min if p.f_min is None else np.asarray(p.f_min, dtype=float)
        f_max = c.f_max if p.f_max is None else np.asarray(p.f_max, dtype=float)
        if np.any(f_min < 0) or np.any(f_min >= f_max):
            raise ValueError("force limits need 0 <= f_min < f_max for every cable")
        border = BorderPolicy(overload_factor=p.overload_factor, rate=p.overload_rate or None)
        d = self.distributor
        if d is None or (d.method, d.backend, d.border) != (p.method, p.backend, border) \
                or not (np.array_equal(d.f_min, f_min) and np.array_equal(d.f_max, f_max)):
            self.distributor = ForceDistributor(self.robot.m, f_min, f_max, method=p.method,
                                                backend=p.backend, border=border)
            if self.level is not None:
                self._set_level(self.level)
        self.params = p
        self.f_ref_override = None               # a parameter change wins over an explicit f_ref
        if p.T_d_w != self.smith.T_d_w:
            self.smith.set_delay(p.T_d_w)
        self.wrench_filter.set_time_constant(p.T_wrench_filter)
        self._eigen_in = 0                       # a known payload's filter times again from the next period
        weight = self.robot.platform.mass * float(np.linalg.norm(self.robot.gravity))
        radius = float(np.mean(np.linalg.norm(self.robot.b, axis=1)))
        self.w_dist_max = p.wrench_deviation_max * weight * np.r_[np.ones(3), np.full(3, radius)]

    def set_reference(self, f_ref) -> None:
        """An explicit reference force per cable (service), within [f_min, f_max]."""
        f_ref = np.asarray(f_ref, dtype=float)
        d = self.distributor
        if f_ref.shape != (self.robot.m,) or not np.all(np.isfinite(f_ref)) \
                or np.any(f_ref < d.f_min) or np.any(f_ref > d.f_max):
            raise ValueError(f"f_ref needs {self.robot.m} values within [f_min, f_max]")
        self.f_ref_override = f_ref
        d.set_reference(f_ref)

    def _set_level(self, level: float) -> None:
        self.level = level
        d = self.distributor
        d.set_reference(d.f_min + level * (d.f_max - d.f_min))

    def _ramp_level(self) -> None:
        target, rate = self.params.tension_level, self.params.tension_rate
        if self.level is None or rate == 0.0:
            self._set_level(target)
        elif self.level != target:
            step = rate * self.dt
            self._set_level(self.level + float(np.clip(target - self.level, -step, step)))

    def payload_wrench(self, x_d, xdot_d, xddot_d, mass: float, cog) -> np.ndarray:
        """The model wrench of a payload (a point mass [kg] at cog (3,) [m], platform frame) at the
        set-point (:func:`cdpr_control.control.load_compensation.payload_wrench`), for ``w_model``:
        its mass-free part kept while the set-point and the cog repeat, times the mass of the period."""
        x_d, xdot_d, xddot_d, cog = (np.asarray(v, dtype=float) for v in (x_d, xdot_d, xddot_d, cog))
        key = (x_d.tobytes(), xdot_d.tobytes(), xddot_d.tobytes(), cog.tobytes())
        return payload_wrench_of_mass(
            self._payload_memo(key, payload_kinematics, self.robot, x_d, xdot_d, xddot_d, cog), mass)

    def _feed_forward(self, x_d, w_dyn, w_model) -> np.ndarray | None:
        """w_ff = PT1_ff(w_model) (6,) of this period, None without a known payload; the filters'
        time constants from ω_n (:func:`loop_filter_times`), evaluated every EIGEN_PERIODS periods
        at the last distribution's forces. Without a payload the disturbance filter returns to
        ``T_wrench_filter`` and w_ff to zero."""
        T = self.params.T_wrench_filter
        if w_model is None:
            if self.payload_filter.y is not None:      # the payload went: back to the filter of no payload
                self.payload_filter.reset(None)
                self.w_ff = np.zeros(6)
                self._eigen_in = 0
                self.wrench_filter.set_time_constant(T)
            return None
        if self._eigen_in <= 0 and self.f_d is not None:
            mass = self.robot.platform.mass * total_mass_ratio(w_dyn, w_model)
            T_dist, T_ff = loop_filter_times(T, vertical_eigenfrequency(self.robot, x_d, self.f_d, mass))
            self.wrench_filter.set_time_constant(T_dist)
            self.payload_filter.set_time_constant(T_ff)
            self._eigen_in = EIGEN_PERIODS
        self._eigen_in -= 1
        if self.payload_filter.y is None:
            self.payload_filter.reset(np.zeros(6))      # the payload enters from zero, not by a step
        self.w_ff = self.payload_filter.update(w_model).copy()
        return self.w_ff

    def set_user_wrench(self, w_user) -> None:
        """Hand guiding (section 5.2): the user's wrench w_Adm (6,) [N, N m] of the admittance
        controller (5.9) in this period, None while nobody guides (:meth:`_hand_reserve`)."""
        self.w_user = None if w_user is None else np.asarray(w_user, dtype=float)

    def _hand_reserve(self, AT) -> None:
        """The hand's reserve r [N] of this period while a user guides (:meth:`_with_reserve`).

        A departure from the thesis, which plans the minimal tension whatever the user does: the
        cable forces that balance the hand's wrench h, Δf = -(A^T)^+ h, leave at once when the
        hand lets go, faster than the measured-wrench filter and the CFC follow, and the cable that
        carried them rings below f_min at the platform's cable mode (docs/admittance.md: 2.5 N for
        f_min 5 N on the Mini after a 13 N push). r is the largest |Δf_i|: it rises with the
        user's wrench at the tension level's rate (``tension_rate``; the forces it adds move at that
        rate too, :meth:`_with_reserve`) and decays with RESERVE_RELEASE_TIME after the hand has let
        go, so the reserve is there while the cables ring out. Without a user
        (``set_user_wrench(None)``) r decays to 0. The target is RESERVE_RING times the largest
        |Δf_i| (2: the release's swing, not only the static change, which let #28 of the Mini's
        grid ring to 4.49 N for f_min 5 N, see RESERVE_RING)."""
        target = 0.0 if self.w_user is None else RESERVE_RING * float(np.abs(user_forces(AT, self.w_user)).max())
        if target >= self.reserve:
            d = self.distributor
            rate = self.params.tension_rate * float(np.max(d.f_max - d.f_min))
            self.reserve = target if rate == 0.0 else min(target, self.reserve + rate * self.dt)
        else:
            self.reserve += (target - self.reserve) * min(1.0, self.dt / RESERVE_RELEASE_TIME)
            if self.reserve < RESERVE_FLOOR:
                self.reserve = 0.0

    def _with_reserve(self, AT, result: DistributionResult) -> DistributionResult:
        """The distribution again with every cable within [f_min + r, f_max - r]: the hand's reserve r
        kept from both limits (a release swings the cables it unloads down and those it loads up),
        at most the largest margin this pose and wrench leave (:func:`largest_margin`), so that the
        set-point stays continuous near the border; ``result`` where no margin is left.

        The cable forces the reserve adds move at most at the tension level's rate (``tension_rate``
        times the force range, per cable and period), not only r: raising the bounds of the cables
        at a limit moves the others along the null space of A^T, by up to 18 N per N of r at the
        IPAnema 3's grid pose #12 (two low cables whose null-space rows are nearly parallel). With
        r alone rate-limited, f_d rose at up to 58 kN/s there, faster than the CFC follows; the
        cables' unequal lag read as a wrench, which (5.9) took for the user's and which raised r
        again: with RESERVE_RING 2 the loop ran away into a 13 Hz oscillation until the force watch
        held (docs/validation.md, "Hand guiding after session 12"). The set-point is therefore
        f = f_plain + s (f_raised - f_plain), s in [0, 1] the largest for which no cable's addition
        moves by more than the rate's step from the last period's (``reserve_forces``): both
        solutions balance A^T f = -w_d, so their combination does, within [f_min + s r, f_max - s r]
        (``reserve_applied`` = s r, the reserve kept); s = 1 (the raised QP's optimum) once the
        additions have caught up."""
        d = self.distributor
        if self.reserve == 0.0 or d.method != "qp" or result.status != Status.FEASIBLE:
            return self._reserve_kept(result, 0.0, None)
        r = min(self.reserve, RESERVE_SHARE * self.margin_lp.solve(AT, self.w_d, d.f_min, d.f_max))
        raised = d.qp.solve(AT, self.w_d, f_min=d.f_min + r, f_max=d.f_max - r) if r > 0.0 else None
        if raised is None or raised.status != Status.FEASIBLE:
            return self._reserve_kept(result, 0.0, None)
        added = raised.f - result.f
        rate = self.params.tension_rate * float(np.max(d.f_max - d.f_min))
        if rate > 0.0:
            step, last = rate * self.dt, self.reserve_forces
            with np.errstate(divide="ignore", invalid="ignore"):
                bound = np.where(added > 0.0, (last + step) / added,
                                 np.where(added < 0.0, (last - step) / added, np.inf))
            s = float(np.clip(bound.min(), 0.0, 1.0))
            if s < 1.0:
                r, added = s * r, s * added
                raised = replace(raised, f=result.f + added)
        raised = replace(raised, f_min=result.f_min, f_max=result.f_max, violation=result.violation)
        return self._reserve_kept(raised, r, added)

    def _reserve_kept(self, result: DistributionResult, r: float, added) -> DistributionResult:
        """Remember the reserve r [N] a set-point keeps and the forces it added (None: none)."""
        self.reserve_applied = r
        if added is None:
            self.reserve_forces[:] = 0.0
        else:
            self.reserve_forces[:] = added
        return result

    @staticmethod
    def _within_limits(result: DistributionResult) -> DistributionResult:
        """While a user guides: forces outside [f_min, f_max] (the hand pushes a wrench the pose cannot
        balance within them, and the distribution returns its least-violating forces, section 3.6.2)
        clipped to the limits; status and violation still say that the wrench had no solution.

        A departure from the thesis (which does not guide beyond the workspace's capacity): the
        clipped forces do not balance the hand, so the platform gives way to it instead of the
        drives being sent a force beyond f_max; where the hand goes on pushing, the force watch
        holds on the measured forces (docs/admittance.md, docs/validation.md "Hand guiding after
        session 11": up to 0.26 N above f_max before the hold at the Mini's border poses)."""
        f = np.clip(result.f, result.f_min, result.f_max)
        return result if np.array_equal(f, result.f) else replace(result, f=f)

    def _contact_wrench(self, contact) -> np.ndarray | None:
        """Section 5.1.2: the correction that puts the expected contact reaction into the distributed
        wrench (:func:`expected_contact_wrench_of`) of contact = (state letter, F_d,0 (3,), F_vec (3,))
        of the hybrid force controller; None while it does not act."""
        state, F_d0, F_vec = contact
        F_d0 = np.asarray(F_d0, dtype=float)
        self.z_t = self._task_axis(F_d0.tobytes(), task_axis, F_d0, self.z_t)   # (an unchanged F_d,0: the same axis)
        if state not in FORCE_CONTROLLED:        # idle: the expected contact wrench is zero
            return None
        return expected_contact_wrench_of(state, F_d0, F_vec, self.z_t)

    def update(self, x_d, xdot_d, xddot_d, w, w_model=None, contact=None, AT=None) -> DistributionResult:
        """Desired pose, twist, acceleration and the measured wrench -> the distribution f_d.

        AT: A^T (2.10) at x_d when the caller has it (ControlLoop's :func:`cdpr_control.kernels.setpoint_ik`),
        else taken here (:func:`cdpr_control.kernels.inverse_kinematics_fields`) of the same computation.

        w_model: a known wrench beyond the platform's own (an identified payload, load_compensation):
        it is not part of the saturated disturbance of (3.24), and the model-only set-point (3.1)
        includes it. contact: (state, F_d,0, F_vec) of the hybrid force controller in this period
        (:class:`cdpr_control.control.hybrid_force_control.HPFCState`'s state, F_d0, F_vec), or None
        without one: while it acts, its desired contact force replaces the measured one in w.
        """
        if self.f_ref_override is None:
            self._ramp_level()
        w_dyn = kernels.platform_wrench(self.robot, x_d, xdot_d, xddot_d)   # (2.33), A^T f = -w
        if AT is None:
            AT, = kernels.inverse_kinematics_fields(self.robot, x_d, "AT")    # (2.10)
        if contact is not None and self.wrench_filter.y is not None:
            # (not into the filter's first sample, which would start it at the full contact force:
            # the expected contact force enters through the filter, from zero)
            dw = self._contact_wrench(contact)
            if dw is not None:
                w = w + dw
        if self.w_d is None:
            self.smith.reset(w_dyn)          # the delay line starts at the model wrench of t = 0
        if self.params.wrench_source == "measured" and all_finite(w):
            # in contact the measured wrench holds the contact reaction, which an identification reads
            # as payload: the feed-forward and its filters stay as they were before the contact
            in_contact = contact is not None and contact[0] != "I"
            w_ff = (self.w_ff if self.payload_filter.y is not None else None) if in_contact \
                else self._feed_forward(x_d, w_dyn, w_model)
            if w_ff is None:
                self.w_d = self.smith.update_filtered(w, w_dyn, self.w_dist_max,    # (3.26), disturbance
                                                      self.wrench_filter)           # filtered, saturated
            else:                     # the payload fed forward; the filter and the saturation see the rest
                self.w_d = self.smith.update_filtered(np.asarray(w, dtype=float) - w_ff, w_dyn,
                                                      self.w_dist_max, self.wrench_filter) + w_ff
        else:
            self.w_d = w_dyn if w_model is None else w_dyn + w_model          # (3.1)
        result = self.distributor.solve(AT, self.w_d, self.dt)               # (3.27)-(3.28)
        if self.w_user is not None or self.reserve > 0.0:
            self._hand_reserve(AT)
            result = self._within_limits(self._with_reserve(AT, result))
        self.f_d = result.f
        return result

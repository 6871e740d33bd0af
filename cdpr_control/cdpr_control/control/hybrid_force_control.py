"""Hybrid position and force control (HPFC), thesis section 5.1, Fig. 5.3 and Fig. 5.4.

The CNC (the G-code interpolator) delivers the path x_d and the desired force F_d,0 (force axes
U V W, base frame, the force the platform exerts on the environment). This module turns them and
the measured wrench w into the position offset x_d,HPFC of (5.1),

    θ_d = IK{x_d + x_d,HPFC} + Δq_d,CFC ,

which the joint command adds like every other offset input (:mod:`cdpr_control.control.offset_inputs`).

- Task frame (5.2): R_t has its z axis along F_d,0, so F_d,t = R_t^T F_d,0 = [0 0 F_d]; the
  contact force F is the same projection of the measured contact force vector.
- Contact force: the measured wrench minus the weight of the platform and of a known payload,
  F_vec = -(w_F - (m_p + m_load) g) (w is the external wrench on the platform, A^T f = -w, (2.10);
  the platform pushes the environment with the opposite of what the environment pushes it with),
  tared when an approach starts (``tare``): what it reads then, if below F_th / 2, is taken for the
  sensors' offsets and the weight model's error, not contact, and is subtracted until the next
  approach (above F_th / 2 the platform is taken to touch already, and nothing is tared).
- State machine of Fig. 5.4: A approach along the task z axis at v_max,HPFC until F >= F_th;
  B brake to standstill; D closed-loop force control with the PID (5.3); C contact lost
  (F < F_th in D): approach again. The output is x_t along the task z axis, x_d,HPFC = R_t [0 0 x_t].
- Release (not in Fig. 5.4, see docs/hybrid_force_control.md): when the desired force falls below
  F_th or the controller is disabled, x_t returns to zero at v_max,HPFC with the same
  acceleration limit (state R), then the controller is idle (state I) and the platform is back
  under pure position control at the programmed pose, without a jump.
- PID (5.3) on e_F = F_d - F with output saturation |x_t| <= x_max and anti-windup (conditional
  integration and clamping as :mod:`cdpr_control.control.pi_control`); the D part acts on the (low-pass
  filtered) measured force only, so a step of F_d does not kick the output.
- Section 5.1.2's changes of the cable force control (:class:`CFCCoupling`): paused in A-C,
  running in D and R with its feed-forward through a moving average of T_MA,HPFC; the force
  distribution's wrench carries the expected contact force (:func:`expected_contact_wrench`).

Units: (5.3) is printed as x_t / e_F = K_p (1 + 1/(s T_i) + s T_d) with K_p = 22,000 N/m "gain
(stiffness)" (table 5.1); a position per force is m/N, so the gain applied is 1 / K_p: the
controller moves by the force error divided by the expected stiffness of robot and environment.
Table 5.1's unit of T_d (s^-1) is read as s (a derivative time constant).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import daqp
import numpy as np

from cdpr_control import kernels
from cdpr_control.control.filters import LowPass
from cdpr_control.control.safety import all_finite
from cdpr_control.force_distribution.methods import distribute
from cdpr_control.force_distribution.result import Status
from cdpr_control.model.dynamics import gravity_wrench
from cdpr_control.model.memo import Memo

IDLE, APPROACH, BRAKE, LOST, CONTACT, RELEASE = "I", "A", "B", "C", "D", "R"
NO_TARE = np.zeros(3)   # HybridForceControl.F_tare without a tare (shared, read-only: +0.0 each)
NO_TARE.flags.writeable = False
STATES = (IDLE, APPROACH, BRAKE, LOST, CONTACT, RELEASE)
STATE_NAMES = {IDLE: "idle (position control)", APPROACH: "approach", BRAKE: "brake", LOST: "contact lost",
               CONTACT: "force control", RELEASE: "release"}
# The task z axis is not position-controlled (Fig. 5.2) while x_t acts: A-D and the release R.
FORCE_CONTROLLED = (APPROACH, BRAKE, LOST, CONTACT, RELEASE)
HAND_OVER_TIME = 0.2    # s, ramp of the contact force from x_t to the CFC's feed-forward (ASSUMPTION)
# The CFC pauses during contact establishment (A-C, section 5.1.2); it runs in D and R
# (ContactCableForceControl, in ControlLoop and in the node cable_force_controller). In A, before
# the impact, it first tensions the cables for the contact to come (pre_contact_forces) and holds
# that from B on: its output x_comp hands nothing over in A-C (no contact force pressed by it).
CFC_PAUSED = (APPROACH, BRAKE, LOST)
# s, the ramp of the CFC's set-point in A from the free-space forces to the pre-contact ones
# (pre_contact_forces; ASSUMPTION: within the joint command's 0.5 s switch-on ramp, T_on, that x_t
# waits in A, and slow against the CFC's T_i 0.1 s and T_1,r 0.08 s)
PRE_TENSION_TIME = 0.3
# s the CFC then runs on the pre-contact forces before it pauses: its PI settles on them (T_i 0.1 s,
# T_1,r 0.08 s). Paused at the ramp's end, the error and the PI's output near its saturation at the
# pause clipped its integral part at the resumption in D, and the drive command stepped by 0.68 mm
# (the floor program through the graph). Ramp and settling end before x_t leaves 0 (T_on 0.5 s).
PRE_TENSION_SETTLE = 0.15
# s, PT1 time constant of the CFC's bias along a against the hybrid force controller's error
# (CFCCoupling.run; ASSUMPTION): slow against the CFC's loop (T_i 0.1 s, T_1,r 0.08 s), whose fast
# part along a it keeps, fast against the PID's T_i (2.6 s). With T_MA (2 s, until session 13) the
# CFC took back what x_t pressed for seconds (IPAnema 3 #17, seed 2: 1,565 N/m of the 22,143 N/m met
# in B) and the contact force crept towards F_d (-4.0 % after 4.6 s; docs/hybrid_force_control.md,
# "Session 14")
BIAS_TIME = 0.5
# B ends at standstill, below V_END v_max, or after B_MARGIN times its profile at stiffness K_p
# (HybridForceControl._brake_limit); ASSUMPTIONS, not in the thesis (docs/hybrid_force_control.md)
V_END = 0.02
B_MARGIN = 3.0
# B's top speed keeps the contact force's filter lag at stiffness K_p within this share of F_d
# (HybridForceControl._brake_speed; ASSUMPTION, docs/hybrid_force_control.md)
LAG_SHARE = 0.1
# the stiffness B measures is taken as at least this share of K_p (a force that hardly rises yet
# would plan a stroke of metres; ASSUMPTION)
K_MIN = 0.25
# A and C approach at most so fast that the force the drives' lag and the contact force's PT1 carry
# past the detection at F_th at stiffness K_p is this share of F_d - F_th (approach_speed; ASSUMPTION,
# session 13: the other half for B's braking and contacts stiffer than K_p)
APPROACH_LAG_SHARE = 0.5
# The force the controller regulates is limited to the pose's contact capacity (contact_capacity) over
# 1 + CAPACITY_OVERSHOOT: the largest transient the validation's bands accept, an overshoot of 20 %
# of F_d (table 5.2: 11.3 % max), then still asks forces the distribution can plan within its
# limits (the lead's decision in session 12; docs/hybrid_force_control.md, "Beyond the pose's capacity")
CAPACITY_OVERSHOOT = 0.2
# Contact is refused where the force the controller would regulate (F_d, limited to the capacity as
# above) is below F_th / (1 - CAPACITY_OVERSHOOT): the accepted transient's lower edge, F_d (1 -
# 0.2), would then be below the contact threshold F_th at which D takes the contact for lost (Fig.
# 5.4: D -> C, a new approach and impact), so the band cannot be held by construction (session 13;
# docs/hybrid_force_control.md, "Session 13"). Below F_th itself the controller would not even start.
MIN_CONTACT_FACTOR = 1.0 / (1.0 - CAPACITY_OVERSHOOT)
# in D the P part of (5.3) divides by at least this times the stiffness met in B (_pid_stiffness):
# the contact loop's gain margin (cdpr_control.analysis.contact_margin, the platform's cable-side
# force and the drive behind the hold) over the 80 cases of the contact sweep is at least 6.24 dB
# with 1 on the robot file's drive (IPAnema 3 #33, seed 2, 1e5 N/m, 500 N), 4.97 dB on seed 2's own
# drive there, 4.81 dB with the mismatched plant's largest extra dead time (1.5 ms). 1.15 gave 6 dB
# in all three and passed the sweep 80/80, but the Mini's 3 N approach on 1.3 K_p then overshot
# its 10 % by 0.07 N: not kept (docs/hybrid_force_control.md, "Contact margin (session 14)")
P_MARGIN_FACTOR = 1.0
# s: /diagnostics while a reason's numbers change (F_d limited, moving x_d): at most once per this
# (ContactDiagnostics); a change of level or reason is reported at once
DIAGNOSTICS_REPEAT = 1.0
OK, WARN, ERROR = 0, 1, 2           # diagnostic levels (diagnostic_msgs/DiagnosticStatus's, as ints)
# -: the cable force controller's saturation F_sat,n / F_sat,p (3.19) is this many times wider in D and
# R (ASSUMPTION, session 13). The saturation limits the CFC's influence on the position (section
# 3.5.2); in D the task axis is force-controlled, and the corrections the CFC has to make grow with
# the cable force changes the contact brings (hundreds of N on the IPAnema 3's lower cables): the
# cables settle under them (section 4.1.3; the default plant's settlement, 0.3 of the extra force's
# elastic strain) and the plant's geometry and stiffness errors scale with them. With the printed
# saturation the outputs sat at it through D at border poses and the contact force stayed 5-40 %
# low (docs/validation.md, "Contact after session 13"). After the contact the saturation returns to
# F_sat as far as the output held allows (ContactCableForceControl._saturation: no step)
CONTACT_SATURATION = 4.0


@dataclass
class HPFCParams:
    """Parameters of the hybrid position and force control (defaults: table 5.1, IPAnema 3)."""

    K_p: float = 22000.0         # N/m, proportional gain (stiffness), table 5.1; output gain is 1/K_p
    T_i: float = 2.6             # s, integrator reset time, table 5.1
    T_d: float = 0.03            # s, derivative time constant, table 5.1
    T_MA: float = 2.0            # s, moving average of the CFC's wrench input, table 5.1
    F_th: float = 25.0           # N, threshold force of contact detection, table 5.1
    v_max: float = 0.05          # m/s, maximal approach velocity, table 5.1
    a_max: float = 0.5           # m/s^2, acceleration of x_t in A, B, C, R (ASSUMPTION: braking from
                                 # 50 mm/s takes 0.1 s and 2.5 mm)
    x_max: float = 0.1           # m, saturation of x_t, also the farthest approach (ASSUMPTION)
    T_F: float = 0.05            # s, PT1 on the contact force (ASSUMPTION: sensor noise, D part)
    payload: float = 0.0         # kg, known payload whose weight is no contact force
    tare: bool = True            # zero the contact force at the start of an approach (reading < F_th / 2)
    k_env: float = 0.0           # N/m, the stiffest surface expected; the approach is slowed so that the
                                 # impact of the platform's mass on it stays below F_d (0: v_max always)
    d_env: float = 0.0           # N s/m, that surface's damping: at the impact it pushes back with d_env v
                                 # besides the spring's v sqrt(k_env m) (approach_speed)
    T_on: float = 0.0            # s, the joint command's switch-on ramp of this output (its transfer_time):
                                 # x_t leaves 0 in A no earlier than T_on after the output is reported
                                 # active (not in the thesis, docs/hybrid_force_control.md)

    def validate(self) -> None:
        checks = {"K_p": self.K_p > 0.0, "T_i": self.T_i > 0.0, "T_d": self.T_d >= 0.0, "T_MA": self.T_MA >= 0.0,
                  "F_th": self.F_th > 0.0, "v_max": self.v_max > 0.0, "a_max": self.a_max > 0.0,
                  "x_max": self.x_max > 0.0, "T_F": self.T_F >= 0.0, "payload": self.payload >= 0.0,
                  "T_on": self.T_on >= 0.0, "k_env": self.k_env >= 0.0, "d_env": self.d_env >= 0.0}
        bad = [k for k, ok in checks.items() if not (ok and np.isfinite(getattr(self, k)))]
        if bad:
            raise ValueError(f"invalid HPFC parameters: {', '.join(f'{k}={getattr(self, k)}' for k in bad)}")


def drive_ramp_lag(drive) -> float:
    """The time [s] by which a drive's position follows a ramp of its command (its velocity lag):
    T_d + T_1 for the PT1 with dead time (3.10), T_d + 2 zeta T_w for the second-order drive (5.11)."""
    if drive.model == "second_order":
        return drive.T_d + 2.0 * drive.zeta * drive.T_w
    return drive.T_d + drive.T_1


def _clip(value: float, bound: float) -> float:
    """value limited to [-bound, bound] (scalar; np.clip costs microseconds per call)."""
    return max(-bound, min(bound, float(value)))


def task_axis(F_d0, z_previous=None) -> np.ndarray:
    """z axis of the task frame (3,): the direction of F_d,0 (5.2). F_d,0 = 0 has no direction:
    then z_previous (the last task z axis) is kept, or e_z when there is none."""
    F = np.asarray(F_d0, dtype=float)
    norm = math.sqrt(float(F @ F))
    if norm > 0.0 and math.isfinite(norm):
        return F / norm
    return np.array([0.0, 0.0, 1.0]) if z_previous is None else np.asarray(z_previous, dtype=float)


def task_frame(F_d0, z_previous=None) -> np.ndarray:
    """R_t (3, 3) of the task frame: z axis along F_d,0 (5.2), so that R_t^T F_d,0 = [0 0 |F_d,0|].

    The x axis is the base axis least parallel to z, made orthogonal (deterministic, continuous
    while F_d,0 turns by less than that axis); z as :func:`task_axis`. The controller itself needs
    only the z axis: F_d = z_t . F_d,0, F = z_t . F_vec, x_d,HPFC = x_t z_t.
    """
    z = task_axis(F_d0, z_previous)
    e = np.eye(3)[int(np.argmin(np.abs(z)))]
    x = e - (e @ z) * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def contact_force(w, mass: float, gravity) -> np.ndarray:
    """Force vector (3,) the platform exerts on the environment: -(w_F - m g) (section 5.1.2).

    w is the measured wrench (6,) of (2.11) (external wrench on the platform, gravity included),
    mass the platform's plus a known payload's [kg], gravity (3,) [m/s^2].
    """
    return -(np.asarray(w, dtype=float)[:3] - mass * np.asarray(gravity, dtype=float))


def select_position_feedback(x_d, x, z_t) -> np.ndarray:
    """The pose feedback for position control with the task z axis force-controlled (Fig. 5.2).

    Raibert and Craig's selection matrix applied to the pose error: the returned x' gives
    x_d - x' = (I - S) (x_d - x) with S = z_t z_t^T on the translation, so an operational-space
    position controller does not act (and does not integrate) along the force direction.
    """
    x_d, x = np.asarray(x_d, dtype=float), np.asarray(x, dtype=float)
    z = np.asarray(z_t, dtype=float)
    out = x.copy()
    out[:3] += z * (z @ (x_d[:3] - x[:3]))
    return out


class MovingAverage:
    """Mean of the last N = max(1, round(T / dt)) samples of a vector signal (running sum, ring buffer).

    The first sample (or :meth:`reset`) fills the window, so the output starts without transient.
    """

    def __init__(self, T: float, dt: float):
        if not (T >= 0.0 and dt > 0.0):
            raise ValueError(f"need T >= 0 s and dt > 0 s, got T={T}, dt={dt}")
        self.dt = dt
        self.n = max(1, int(round(T / dt)))
        self.T = T
        self.buffer: np.ndarray | None = None
        self.y: np.ndarray | None = None

    def reset(self, value=None) -> None:
        if value is None:
            self.buffer = self.y = None
            return
        value = np.array(value, dtype=float)
        self.buffer = np.tile(value, (self.n, 1))
        self.index = 0
        self.sum = value * self.n
        self.count = 0
        self.y = value.copy()

    def update(self, u) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        if self.buffer is None:
            self.reset(u)
            return self.y
        self.sum += u - self.buffer[self.index]
        self.buffer[self.index] = u
        self.index = (self.index + 1) % self.n
        self.count += 1
        if self.count >= self.n:                 # recompute now and then: no drift of the running sum
            self.sum = self.buffer.sum(axis=0)
            self.count = 0
        self.y = self.sum / self.n
        return self.y


@dataclass
class HPFCState:
    """What one period computed (the content of ``hybrid_force_controller/state``)."""

    state: str                   # I, A, B, C, D, R
    active: bool                 # output in use (enabled, or releasing after a disable)
    z_t: np.ndarray              # (3,) task z axis (direction of F_d,0) in the base frame
    F_d0: np.ndarray             # (3,) desired force F_d,0 [N], base frame
    F_vec: np.ndarray            # (3,) measured contact force vector (filtered) [N], base frame
    F_d: float                   # desired force along z_t [N] (5.2)
    F: float                     # measured contact force along z_t [N]
    e_F: float                   # F_d - F [N]
    x_t: float                   # offset along z_t [m]
    v_t: float                   # its rate [m/s]
    integrator: float            # integral part of x_t [m]
    saturated: bool              # |x_t| at x_max
    x: np.ndarray                # (6,) x_d,HPFC = [R_t [0 0 x_t]; 0 0 0] [m, rad]
    F_d_requested: float = math.nan   # N, the F_d asked for (F_d,0 of the set-point along z_t) where it was
                                 # limited to the pose's capacity (F_d, F_d0 then the limited ones); NaN: not limited
    capacity: float = math.inf   # N, the pose's contact capacity (contact_capacity) where known, else inf
    refused: bool = False        # contact refused at x_d: the force it could regulate, min(F_d_requested,
                                 # capacity / (1 + CAPACITY_OVERSHOOT)) where that limited it, is below
                                 # minimum_contact_force; the controller releases (R, I), F_d and F_d,0
                                 # are 0 and F_d_requested says what was asked


class HybridForceControl:
    """The contact state machine of Fig. 5.4 with the PID (5.3): F_d,0 and w -> x_d,HPFC."""

    idle_path = True        # state I unwanted through _idle_state (False: the full path, its reference)

    def __init__(self, robot, dt: float, params: HPFCParams | None = None, enabled: bool = False):
        self.robot = robot
        self.dt = dt
        self.enabled = enabled
        self.state = IDLE
        self.z_t = np.array([0.0, 0.0, 1.0])
        self._z_t_of: bytes | None = None      # F_d,0 (its bytes) whose axis z_t is
        self._F_d = 0.0                        # N, F_d of that F_d,0 (5.2)
        self.x_t = 0.0
        self.v_t = 0.0
        self.integrator = 0.0
        self.saturated = False
        self.F_prev: float | None = None
        self.F_tare = NO_TARE                  # N, the contact force measured in free space at the tare
        self.contact = (0.0, 0.0)              # x_t and F when the contact was detected (A/C -> B)
        self.k_contact: float | None = None    # N/m, effective contact stiffness measured in B
        self.k_pid = 0.0                       # N/m, the stiffness (5.3)'s P part divides by in D (_pid_stiffness)
        self.active_periods = 0                # periods the output has been reported active (HPFCState.active)
        self.drive_lag = drive_ramp_lag(robot.drive)   # s, the drives' lag behind a ramp of x_t (_brake_ahead)
        self.brake_periods, self.brake_limit = 0, 0.0   # periods in B, its bound [s] (_brake_limit)
        self.brake_track: deque = deque()      # (x_t, F) of B's last periods: the stiffness met (_brake_ahead)
        self.braking = False                   # B has begun to slow down (it does not speed up again)
        self.brake_speed = 0.0                 # m/s, B's top speed (_brake_speed)
        self.force_filter = LowPass(0.0, dt)
        self.capacity = math.inf               # N, the pose's contact capacity (_limited), inf: not known
        self._capacity = Memo()                # contact_capacity of (x_d, z_t, limits)
        self.capacity_lp = CapacityLP(6, robot.m)
        self._idle = Memo(read_only=True)      # (z_t, F_d,0, x) of the idle state (_idle_state)
        self.set_params(params or HPFCParams())

    def set_params(self, params: HPFCParams) -> None:
        """Apply new parameters live (the state and x_t are kept)."""
        params.validate()
        self.params = params
        self.force_filter.set_time_constant(params.T_F)
        # B's stiffness is the force's rise over x_t's across 2 T_F (at least 2 periods), x_t taken
        # T_F + drive_lag earlier (the PT1's and the drives' lag behind x_t): _brake_ahead
        self.brake_window = max(2, int(round(2.0 * params.T_F / self.dt)))
        self.brake_lag = params.T_F + self.drive_lag
        self.brake_delay = int(round(self.brake_lag / self.dt))
        self.brake_track = deque(self.brake_track, maxlen=self.brake_window + self.brake_delay + 1)
        self.mass = self.robot.platform.mass + params.payload
        self.weight = self.mass * np.asarray(self.robot.gravity, dtype=float)   # m g of contact_force, once
        self._weight = self.weight.tolist()

    def _filter_force(self, w: list[float]) -> np.ndarray:
        """self.force_filter (PT1) of the contact force -(w_F - m g) (:func:`contact_force`) of the
        wrench w (6 floats), on floats (LowPass.update_floats)."""
        self.force_filter.update_floats([-(a - b) for a, b in zip(w[:3], self._weight)])
        return self.force_filter.y

    def _enter(self, state: str) -> None:
        """Leaving force control, the position-controlled x_t starts from rest (the PID's rate of
        change, up to a force error over K_p per period, is no velocity to carry on with)."""
        if self.state == CONTACT:
            self.v_t = 0.0
        self.state = state

    def _brake_limit(self, F_d: float, F: float) -> float:
        """The longest B [s] from a contact detected at F [N]: B_MARGIN times the time of B's
        profile were the effective stiffness K_p (the stroke (F_d - F) / K_p at v_max, which B
        may regain in contact, then braking at a_max)."""
        p = self.params
        return B_MARGIN * (max(0.0, F_d - F) / p.K_p / p.v_max + p.v_max / p.a_max)

    def _brake_speed(self, F_d: float) -> float:
        """B's top speed [m/s]: in contact the impact's limit (approach_speed) is past, so B may be
        faster than A, as long as the filtered force lags by at most LAG_SHARE F_d at stiffness
        K_p (T_F K_p v <= LAG_SHARE F_d: the lead of _brake_ahead corrects the lag, not the
        platform's own dynamics at speed), at most v_max, at least the speed of the detection.
        Kept at the approach's speed the IPAnema 3's floor program settled in 3.6 s instead of 2.3 s;
        at v_max, 150 N on the IPAnema 3 (sweep pose #1) overshot by 27 % (k then at least K_p)."""
        p = self.params
        v_lag = LAG_SHARE * F_d / (p.T_F * p.K_p) if p.T_F > 0.0 else p.v_max
        return max(self.v_t, min(p.v_max, v_lag))

    def _brake_ahead(self, F_d: float, F: float) -> float:
        """B's stroke left [m] to where the force is expected to reach F_d: (F_d - F_lead) / k.

        k is the stiffness met: the rise of the filtered force across B's last 2 T_F over that of
        x_t across the same time T_lag = T_F + drive_lag earlier (:attr:`brake_track`; the force
        follows x_t through the drives (:func:`drive_ramp_lag`) and the PT1 of T_F, also while B
        speeds up), at least K_MIN K_p; K_p (table 5.1's effective stiffness) until measured.
        Planned with K_p, a contact stiffer than K_p ran 20-40 % past F_d, a softer one (the
        IPAnema 3 at home, about 12,600 N/m) crept towards it for seconds (issue 25).
        F_lead = F + T_lag k v_t is the force the drives and the PT1 lag behind at the speed v_t (a
        ramp of slope k v_t through a lag of T lags by T k v_t): planned on F alone, B stopped where
        the filtered force reached F_d, the true one that much beyond; with T_F alone the Mini's
        3 N contact ran 21.5 % past F_d (its drives follow 16.3 ms late, (5.11); sweep pose #0).
        """
        p = self.params
        track = self.brake_track
        track.append((self.x_t, F))
        k = p.K_p
        if len(track) == track.maxlen:
            x_1, x_0 = track[-1 - self.brake_delay][0], track[0][0]
            F_0 = track[self.brake_delay][1]
            if x_1 - x_0 > 0.0 and F - F_0 > 0.0:
                k = max(K_MIN * p.K_p, (F - F_0) / (x_1 - x_0))
        return max(0.0, F_d - F - self.brake_lag * k * self.v_t) / k

    def approach_speed(self, F_d: float) -> float:
        """The speed of A and C [m/s]: v_max, or less where the platform's mass m (with a known
        payload) hitting a surface of stiffness k_env and damping d_env at v could press more than
        F_d at the impact alone, before any control acts: v (sqrt(k_env m) + d_env) bounds that
        press (a mass on a spring and damper in parallel: the spring stores at most the kinetic
        energy, k delta <= v sqrt(k m); the surface is entered at most at v, d delta' <= d v).
        Also at most APPROACH_LAG_SHARE (F_d - F_th) / (K_p (T_F + T_a)): the force still on its way
        when contact is detected (below). Not in the thesis, which approaches at v_max,HPFC and names
        the overshoot its price."""
        p = self.params
        v = p.v_max
        impedance = math.sqrt(p.k_env * self.mass) + p.d_env        # N s/m
        if impedance > 0.0:
            v = min(v, max(F_d, p.F_th) / impedance)
        # contact is detected at F_th at the earliest, and the force the drives' lag and the PT1 of T_F
        # still carry then, K_p v T_lag (the lead of _brake_ahead), comes on top whatever B does: it
        # may use APPROACH_LAG_SHARE of what is left to F_d (the rest: B's braking, a contact stiffer
        # than K_p). Session 13: the Mini's 3 N at 2 mm/s carried 1.6-2.1 N past a detection at 1.1 N,
        # 20.6 % overshoot at #20 (seed 1, 2e6 N/m); slower only for small forces (the IPAnema 3 at 150
        # N: 50 mm/s, above its k_env bound)
        T_lag = p.T_F + self.drive_lag
        if T_lag > 0.0 and F_d > p.F_th:
            v = min(v, APPROACH_LAG_SHARE * (F_d - p.F_th) / (p.K_p * T_lag))
        return v

    def _move(self, v_target: float) -> None:
        """x_t towards the velocity v_target with |dv/dt| <= a_max (approach, brake, release)."""
        dv = self.params.a_max * self.dt
        self.v_t += _clip(v_target - self.v_t, dv)
        self.x_t += self.v_t * self.dt

    def _release(self) -> None:
        """Back to x_t = 0 at most at v_max, braking in time (v^2 = 2 a |x_t|), no overshoot of 0."""
        p = self.params
        distance = abs(self.x_t)
        v_stop = math.sqrt(2.0 * p.a_max * distance)
        target = -math.copysign(min(p.v_max, v_stop), self.x_t)
        self._move(target)
        if self.x_t * (self.x_t - self.v_t * self.dt) <= 0.0 or distance < 1e-9:  # crossed or reached 0
            self.x_t = self.v_t = 0.0
        if self.x_t == 0.0:
            self.state = IDLE

    def update(self, F_d0, w, x_d=None, limits=None) -> HPFCState:
        """One period: desired force F_d,0 (3,) [N], measured wrench w (6,), the pose set-point x_d
        (6,) and the force distribution's limits (f_min, f_max) (m,) [N] (either None: not known,
        F_d not limited) -> HPFCState. While wanted or active, F_d is limited to the pose's
        capacity (:meth:`_limited`); the state's F_d,0 and F_d are then the limited ones."""
        p, dt = self.params, self.dt
        F_d0 = np.asarray(F_d0, dtype=float)
        w = np.asarray(w, dtype=float)
        if F_d0.shape != (3,) or not all_finite(F_d0.tolist()):
            F_d0 = np.zeros(3)                                   # no valid demand: release
        key = F_d0.tobytes()
        if key != self._z_t_of:                                  # (the same F_d,0 has the same axis and F_d)
            self.z_t, self._z_t_of = task_axis(F_d0, self.z_t), key
            self._F_d = float(self.z_t @ F_d0)                   # (5.2): the z entry of R_t^T F_d,0
        F_d = self._F_d
        F_d_requested = math.nan
        refused = False
        if (x_d is not None and limits is not None and F_d > 0.0
                and (self.state != IDLE or (self.enabled and F_d >= p.F_th))):
            F_cap = self._limited(x_d, limits)
            if F_d > F_cap:
                F_d_requested, F_d = F_d, F_cap
                F_d0 = F_d * self.z_t
            if F_d < self.minimum_contact_force() and not math.isnan(F_d_requested):
                # the pose's capacity leaves less than the controller can regulate: refused, released
                # as if the force were taken back (R, I); the state says why (an F_d asked for below
                # the minimum where the pose has the capacity is the program's choice, not refused)
                refused, F_d, F_d0 = True, 0.0, np.zeros(3)
                key = F_d0.tobytes()
        w_floats = w.tolist() if w.shape == (6,) else None
        if w_floats is not None and all_finite(w_floats):
            F_vec = self._filter_force(w_floats)                 # contact_force(w, self.mass, g)
        else:                                                    # keep the last estimate
            F_vec = self.force_filter.y if self.force_filter.y is not None else np.zeros(3)
        if self.state == IDLE and self.idle_path and not (self.enabled and F_d >= p.F_th):
            s = self._idle_state(F_d0, key, F_d, F_vec)          # I, not wanted: most periods
            if refused:
                s.F_d_requested, s.capacity, s.refused = F_d_requested, self.capacity, True
            return s
        if self.state == IDLE and self.enabled and F_d >= p.F_th:  # an approach starts: tare
            raw = float(self.z_t @ F_vec)
            # a reading below F_th / 2 is taken for the sensors' offset, above it for contact; a
            # negative one is no contact whatever its size (the environment only pushes back along
            # z_t): IPAnema 3 #5 (seed 2) read -20 N and was not tared (abs until session 12)
            self.F_tare = F_vec.copy() if p.tare and raw < 0.5 * p.F_th else NO_TARE
        elif (self.state == APPROACH and self.x_t == 0.0 and self.F_tare is not NO_TARE
              and float(self.z_t @ (F_vec - self.F_tare)) < 0.5 * p.F_th):
            # tared in free space and x_t still waiting at 0 (T_on): the tare follows the reading
            # (as at the start, what reads F_th / 2 more is contact and not followed). The cable force
            # control's pre-tension (CFCCoupling.pre_tension) changes the cable forces by up to
            # hundreds of N after the approach began, the platform standing; the sensors' slope
            # errors of those changes (1 % on the default plant) read as a contact force, -0.8 N at
            # Mini #28 (seed 1) before the impact: B then stopped on a force that lagged the true one
            # by that much (docs/hybrid_force_control.md, "Session 12")
            self.F_tare = F_vec.copy()
        F_vec = np.array([a - b for a, b in zip(F_vec.tolist(), self.F_tare.tolist())])
        F = float(self.z_t @ F_vec)
        # the unfiltered contact force of this period: the PT1 (T_F, for the PID) lags a rising
        # contact force by T_F, which at 50 mm/s onto a stiff surface is tens of N of overshoot;
        # contact detection while x_t moves uses whichever of the two is higher
        F_now = F if w_floats is None or not all_finite(w_floats) else sum(
            z * (-(a - b) - c) for z, a, b, c in zip(self.z_t.tolist(), w_floats[:3], self._weight,
                                                   self.F_tare.tolist()))
        F_rise = max(F, F_now)
        e_F = F_d - F
        dF = 0.0 if self.F_prev is None else (F - self.F_prev) / dt
        self.F_prev = F

        wanted = self.enabled and F_d >= p.F_th
        if not wanted:
            if self.state not in (IDLE, RELEASE):
                self._enter(RELEASE)
        elif self.state in (IDLE, RELEASE):
            self._enter(APPROACH)
        if self.state == CONTACT and F < p.F_th:                 # Fig. 5.4: contact lost
            self._enter(LOST)
        if self.state in (APPROACH, LOST):
            if (F_rise if self.v_t > 0.0 else F) >= p.F_th:    # (F_rise once x_t moves: start-up transients)
                self._enter(BRAKE)
                self.contact = (self.x_t, F)             # where the contact was detected
                self.brake_track.clear()
                self.braking, self.brake_speed = False, self._brake_speed(F_d)
                self.brake_periods, self.brake_limit = 0, self._brake_limit(F_d, F)
            elif self.active_periods * dt >= p.T_on - 1e-12:
                self._move(self.approach_speed(F_d))
            # else x_t waits at 0 while the joint command ramps the output in (T_on): a moving x_t
            # times a rising ramp would approach, and press after B, faster than v_max
        if self.state == BRAKE:
            # to standstill where the force is expected to reach F_d, braking at a_max at the latest;
            # up to the speed of B (_brake_speed) until the braking begins, then never faster again
            # (the lead T_F k v_t falls with v_t, which would otherwise speed B up again)
            v_stop = math.sqrt(2.0 * p.a_max * self._brake_ahead(F_d, F))
            self.braking = self.braking or v_stop < self.v_t
            self._move(min(self.v_t if self.braking else self.brake_speed, v_stop))
            self.brake_periods += 1
            # standstill, or creeping (v_t < V_END v_max: what is left to go, v^2 / 2 a_max, is below
            # a micrometre), or B has lasted its bound: closed-loop force control. A force that
            # never reads F_d (biased sensors, a softer robot than K_p) no longer keeps B creeping.
            if self.v_t < V_END * p.v_max or self.brake_periods * dt >= self.brake_limit:
                self.v_t = 0.0
                self._enter(CONTACT)
                x_c, F_c = self.contact                          # the stiffness met from contact to here
                if self.x_t - x_c > 0.0 and F - F_c > 0.0:
                    self.k_contact = (F - F_c) / (self.x_t - x_c)
                self.k_pid = self._pid_stiffness()
                # bumpless: the integral part takes over what the P part does not give (the D part
                # of the contact transient is left out: it would stay in the integrator)
                self.integrator = self.x_t - e_F / self.k_pid
        if self.state == CONTACT:
            self._pid(e_F, dF)
        elif self.state == RELEASE:
            self._release()
        if self.state in (APPROACH, LOST, BRAKE, RELEASE):
            self.integrator = self.x_t                           # the position-controlled x_t
            self.saturated = abs(self.x_t) >= p.x_max
            if self.saturated:
                self.x_t = _clip(self.x_t, p.x_max)
                self.v_t = 0.0
        active = self.enabled or self.state != IDLE
        self.active_periods = self.active_periods + 1 if active else 0
        x_t, (z_x, z_y, z_z) = self.x_t, self.z_t.tolist()
        x = np.array([x_t * z_x, x_t * z_y, x_t * z_z, 0.0, 0.0, 0.0])    # R_t [0 0 x_t]
        # (F_vec: the array built above for this state alone)
        return HPFCState(self.state, active, self.z_t.copy(), F_d0.copy(),
                         F_vec, F_d, F, e_F, x_t, self.v_t, self.integrator, self.saturated, x,
                         F_d_requested, self.capacity, refused)

    def minimum_contact_force(self) -> float:
        """The smallest force [N] the controller regulates: F_th / (1 - CAPACITY_OVERSHOOT)
        (:data:`MIN_CONTACT_FACTOR`); where the pose's capacity leaves less (or less is asked) contact
        is refused. Not in the thesis (docs/hybrid_force_control.md, "Session 13")."""
        return MIN_CONTACT_FACTOR * self.params.F_th

    def _limited(self, x_d, limits) -> float:
        """The largest F_d [N] the controller regulates at x_d: the pose's contact capacity along z_t
        (:func:`contact_capacity` with the platform's and the known payload's weight at x_d and the
        distribution's limits, kept while x_d, z_t and the limits repeat) over 1 + CAPACITY_OVERSHOOT;
        :attr:`capacity` keeps the capacity. Not in the thesis (docs/hybrid_force_control.md)."""
        x_d = np.asarray(x_d, dtype=float)
        f_min, f_max = (np.array(v, dtype=float) for v in limits)   # (copies: a node passes read-only arrays)
        self.capacity = self._capacity((x_d.tobytes(), self.z_t.tobytes(), f_min.tobytes(), f_max.tobytes()),
                                       self._capacity_at, x_d, f_min, f_max)
        return self.capacity / (1.0 + CAPACITY_OVERSHOOT)

    def _capacity_at(self, x_d, f_min, f_max) -> float:
        if not (x_d.shape == (6,) and np.all(np.isfinite(x_d)) and f_min.shape == f_max.shape == (self.robot.m,)):
            return math.inf                       # (nothing to plan with: not limited)
        AT, = kernels.inverse_kinematics_fields(self.robot, x_d, "AT")   # (2.10) at x_d
        # the platform's weight and the known payload's (taken at the platform's centre of gravity)
        w_g = gravity_wrench(self.robot, x_d) * (self.mass / self.robot.platform.mass)
        return self.capacity_lp.solve(AT, w_g, self.z_t, f_min, f_max)

    def _idle_state(self, F_d0: np.ndarray, key: bytes, F_d: float, F_vec: np.ndarray) -> HPFCState:
        """The rest of :meth:`update` in state I while not wanted (disabled, or F_d < F_th), after the
        force filter. None of the full path's other branches acts there (no tare, no transition;
        x_t, v_t, the integral part and the saturation flag stay as they are): only F_prev and
        active_periods change, and F_vec, F and e_F are computed as there (the same operations, so
        the same numbers). z_t, F_d,0 and x = R_t [0 0 x_t] are the same each period: read-only
        arrays shared by the periods while z_t, F_d,0 and x_t do not change (the full path copies
        or builds them each period); tests/control/test_hpfc_idle_path.py compares the two paths."""
        # F_vec - 0.0 is F_vec (-0.0 - 0.0 is -0.0): without a tare, a copy
        F_vec = F_vec.copy() if self.F_tare is NO_TARE else np.array(
            [a - b for a, b in zip(F_vec.tolist(), self.F_tare.tolist())])
        F = float(self.z_t @ F_vec)
        self.F_prev = F
        active = self.enabled                                    # (enabled or state != I)
        self.active_periods = self.active_periods + 1 if active else 0
        x_t = self.x_t
        z_t, F_d0, x = self._idle((key, self.z_t.tobytes(), x_t, math.copysign(1.0, x_t)),
                                  self._idle_constants, F_d0, x_t)
        return HPFCState(IDLE, active, z_t, F_d0, F_vec, F_d, F, F_d - F, x_t, self.v_t, self.integrator,
                         self.saturated, x)

    def _idle_constants(self, F_d0: np.ndarray, x_t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(z_t, F_d,0, x) of :meth:`_idle_state`, built as :meth:`update` builds them."""
        z_x, z_y, z_z = self.z_t.tolist()
        return (self.z_t.copy(), F_d0.copy(),
                np.array([x_t * z_x, x_t * z_y, x_t * z_z, 0.0, 0.0, 0.0]))    # R_t [0 0 x_t]

    def _pid_stiffness(self) -> float:
        """The stiffness [N/m] the P part of the PID (5.3) divides the force error by in D: K_p, or
        :data:`P_MARGIN_FACTOR` times the stiffness met in B (:attr:`k_contact`) where that is stiffer
        (the I part keeps 1 / (K_p T_i)). (5.3)'s gain 1/K_p is tuned for contacts of about K_p
        (table 5.1: the IPAnema 3's z stiffness at home); the loop's gain is the stiffness met over
        K_p, and where the cables and the surface are stiffer (border poses) the P part crosses over
        where the drives' lag leaves no phase and the platform stands, its force following the
        winches with the cables' stiffness: a growing 52 Hz oscillation (IPAnema 3 sweep #33, seed 2,
        1e5 N/m, met at 2.1 K_p; docs/hybrid_force_control.md, "Session 14"). The factor keeps the
        loop's gain margin at 6 dB or more over the sweep (:mod:`cdpr_control.analysis.contact_margin`,
        "Contact margin (session 14)"). Never below K_p (a softer contact keeps the thesis's gain)."""
        k = self.params.K_p
        if self.k_contact is not None and math.isfinite(self.k_contact):
            return max(k, P_MARGIN_FACTOR * self.k_contact)
        return k

    def absorb(self, dx: float) -> None:
        """Take over dx [m] along z_t from another output acting on the contact force (in D and R:
        the cable force controller's integral part along the task axis, see ``ControlLoop``): x_t
        and its integral part move by dx, so the sum of both outputs does not change."""
        if self.state in (CONTACT, RELEASE) and math.isfinite(dx):
            self.x_t = _clip(self.x_t + dx, self.params.x_max)
            if self.state == CONTACT:
                self.integrator = _clip(self.integrator + dx, self.params.x_max)

    def _pid(self, e_F: float, dF: float) -> None:
        """(5.3) with gain 1/K_p, D on the measurement, saturation |x_t| <= x_max and anti-windup."""
        p, dt = self.params, self.dt
        pd = (e_F - p.T_d * dF) / (self.k_pid or p.K_p)          # (_pid_stiffness)
        candidate = self.integrator + dt / (p.K_p * p.T_i) * e_F
        free = pd + candidate
        blocked = (free > p.x_max and e_F > 0.0) or (free < -p.x_max and e_F < 0.0)
        self.integrator = _clip(self.integrator if blocked else candidate, p.x_max)
        x_t = pd + self.integrator
        self.saturated = abs(x_t) > p.x_max
        x_new = _clip(x_t, p.x_max)
        self.v_t = (x_new - self.x_t) / dt
        self.x_t = x_new


def task_force_direction(AT, z_t) -> np.ndarray:
    """a (m,): the cable forces' share in the force along the task z axis, a . f = z_t . (A^T f)_F
    (A^T f is the cables' wrench on the platform, (2.10)); a force change orthogonal to a leaves
    the contact force unchanged."""
    return np.asarray(AT, dtype=float)[:3].T @ np.asarray(z_t, dtype=float)


def contact_response(AT, k_l, z_t) -> np.ndarray:
    """e (m,): the cable forces' change [N per N] when the platform presses 1 N along z_t against a
    surface that blocks it there, the rest of the pose free: the elastic response of the cables,
    e = K_l A (A^T K_l A)^-1 g with g = [z_t; 0 0 0], K_l = diag(k_l) the cable stiffness (2.15)-(2.17)
    and A^T K_l A the cable stiffness matrix K_c (2.22) (the geometric part left out). A^T e = g,
    so a . e = 1 (a of :func:`task_force_direction`). It is how x_t along z_t changes the forces of
    a platform in contact (commanded pose into the surface, the cables unchanged otherwise): on the
    IPAnema 3 near the floor the upper cables carry nearly all of it (their a_i is large, the lower
    cables' small), which the force distribution's set with the contact (:func:`expected_contact_wrench`)
    does not."""
    AT = np.asarray(AT, dtype=float)
    k_l = np.asarray(k_l, dtype=float)
    g = np.zeros(AT.shape[0])
    g[:3] = z_t
    return k_l * (AT.T @ np.linalg.solve(AT @ (k_l[:, None] * AT.T), g))


def pre_contact_forces(AT, e, F_d: float, f_from, f_min, f_max) -> np.ndarray | None:
    """The cable forces to hold before the impact (state A) so that pressing F_d [N], which adds
    e F_d (:func:`contact_response`), keeps every cable within [f_min, f_max]: the issue's "force
    planned for contact before impact". With the CFC paused in B as in the thesis (section 5.1.2), x_t
    presses the contact with e F_d on top of what the CFC held at the pause; held at the free-space
    set, the IPAnema 3's upper cables went below f_min in B near the floor (issue 25).

    f_from (m,) is the set-point when A began (the free-space forces). Returned: the forces nearest
    to it with its wrench within [max(f_min, f_min - e F_d), min(f_max, f_max - e F_d)] (the QP
    (3.27)-(3.28) with those limits and f_ref = f_from), so f_from itself where it already keeps
    the cables within their limits under the contact, and only the internal tension (the nullspace
    of A^T) changed otherwise; None where no such forces exist (the pose cannot hold the contact both
    ways: the CFC then holds f_from, as the thesis)."""
    AT, f_from = np.asarray(AT, dtype=float), np.asarray(f_from, dtype=float)
    df = np.asarray(e, dtype=float) * F_d
    lo, hi = np.maximum(f_min, f_min - df), np.minimum(f_max, f_max - df)
    if not (np.all(np.isfinite(f_from)) and np.all(lo <= hi)):
        return None
    result = distribute(AT, -(AT @ f_from), lo, hi, f_from, method="qp")
    return result.f if result.status == Status.FEASIBLE else None


def post_contact_forces(AT, e, F_d: float, f_hold, f_min, f_max) -> np.ndarray | None:
    """The set-point the cable force control resumes from in D: f_hold (m,) [N], held since the
    pause (A-C), whose press e F_d (:func:`contact_response`) the coupling adds along a, with its
    internal tension (the nullspace of A^T) moved so that f_hold + e F_d is within [f_min, f_max]:
    the forces nearest to f_hold with its wrench within [f_min - e F_d, f_max - e F_d] (the QP
    (3.27)-(3.28) with f_ref = f_hold); f_hold itself where it already is (the pre-contact forces
    of :func:`pre_contact_forces` are), None where no such forces exist.

    Where no pre-contact forces hold the whole press before the impact, f_hold + e F_d took a cable
    below f_min for the 2 s the moving average of T_MA took to bring the distribution's internal
    tension (IPAnema 3 #37, seed 2: cable 1's set-point 94.5 N for f_min 150 N, the cable at 74-82 N,
    below the robot's 100 N for 0.24-0.33 s; docs/hybrid_force_control.md, "Session 14")."""
    AT, f_hold = np.asarray(AT, dtype=float), np.asarray(f_hold, dtype=float)
    df = np.asarray(e, dtype=float) * F_d
    lo, hi = np.asarray(f_min, dtype=float) - df, np.asarray(f_max, dtype=float) - df
    if not np.all(np.isfinite(f_hold)) or not np.all(lo <= hi):
        return None
    if np.all(f_hold >= lo) and np.all(f_hold <= hi):
        return f_hold
    result = distribute(AT, -(AT @ f_hold), lo, hi, f_hold, method="qp")
    return result.f if result.status == Status.FEASIBLE else None


def contact_capacity(AT, w, z_t, f_min, f_max) -> float:
    """The largest force F [N] the platform can press along z_t (3,) at rest with cable forces within
    [f_min, f_max] (m,): the largest F for which A^T f = -w + F [z_t; 0 0 0] (the environment
    pushing back with -F z_t, w the rest of the external wrench, (2.10)) has a solution within the
    limits, wrench feasibility (2.40) along a ray (an LP); 0 where not even F = 0 has one. A
    contact force beyond it cannot be planned within the limits whatever the controller does. One
    cold solve of :class:`CapacityLP`."""
    n, m = np.shape(AT)
    return CapacityLP(n, m).solve(AT, w, z_t, f_min, f_max)


class CapacityLP:
    """:func:`contact_capacity` as one DAQP model (as ``force_setpoint.MarginLP``): variables [f (m), F],
    rows A^T f - F [z_t; 0] = -w (n); bounds f_min <= f <= f_max, 0 <= F <= sum(f_max)."""

    def __init__(self, n: int, m: int):
        self.n, self.m = n, m
        self.A = np.zeros((n, m + 1))
        self.bu = np.zeros(m + 1 + n)
        self.bl = np.zeros(m + 1 + n)
        self.sense = np.zeros(m + 1 + n, dtype=np.int32)
        self.sense[m + 1:] = 5                               # the equality rows
        self.cost = np.r_[np.zeros(m), -1.0]                 # max F
        self.no_hessian = np.zeros((m + 1, m + 1))           # an LP

    def solve(self, AT, w, z_t, f_min, f_max) -> float:
        n, m = self.n, self.m
        A, bu, bl = self.A, self.bu, self.bl
        A[:, :m] = AT
        A[:, m] = 0.0
        A[:3, m] = -np.asarray(z_t, dtype=float)
        bl[:m], bu[:m] = f_min, f_max
        bl[m], bu[m] = 0.0, float(np.sum(f_max))
        bu[m + 1:] = bl[m + 1:] = -np.asarray(w, dtype=float)
        x, _, exitflag, _ = daqp.solve(self.no_hessian, self.cost, A, bu, bl, self.sense)
        if exitflag != 1 or not np.isfinite(x[m]):
            return 0.0
        return float(x[m])


def expected_contact_wrench(state: "HPFCState") -> np.ndarray:
    """The correction (6,) that puts the expected contact reaction into the wrench of the force
    distribution (3.26)-(3.28) in place of the measured one: w - (F_d - F) z_t (force part).

    While the hybrid force controller acts (A-D, R) the environment is expected to push the platform
    with -F_d z_t. The distribution then plans for the contact force being established, does not
    step when the contact is made or lost (the sum w_F + (F - F_d) z_t does not contain the
    contact's jump), and after the release (F_d < F_th) its wrench filter holds no memory of the
    contact, so the CFC resuming in I does not press the platform down with the filtered remains
    of the contact force. Idle (I): 0.
    """
    w = np.zeros(6)
    if state is not None and state.state in FORCE_CONTROLLED:
        w[:3] = -(state.F_d - state.F) * state.z_t
    return w


def expected_contact_wrench_of(state: str | None, F_d0, F_vec, z_t) -> np.ndarray:
    """:func:`expected_contact_wrench` from the published state (``hybrid_force_controller/state``:
    the state letter, reference F_d,0, feedback F_vec) and the task z axis z_t (3,)."""
    z = np.asarray(z_t, dtype=float)
    F_d0, F_vec = np.asarray(F_d0, dtype=float), np.asarray(F_vec, dtype=float)
    w = np.zeros(6)
    if state in FORCE_CONTROLLED and np.all(np.isfinite(np.r_[F_d0, F_vec, z])):
        w[:3] = -(float(z @ F_d0) - float(z @ F_vec)) * z
    return w


class CFCCoupling:
    """Section 5.1.2's changes of the cable force control under hybrid force control.

    - The CFC is paused during contact establishment (A-C): its output Δq_CFC is held and its state
      does not change, since the abruptly changing cable forces would destabilise it (thesis).
    - In D and R it runs (:meth:`contact_update`, used by ``ControlLoop`` and the node
      ``cable_force_controller``), its feed-forward through the moving average of T_MA,HPFC, the
      thesis's filter "to slow down the control loop".
    - :meth:`update` is the coupling without the structure matrix: it holds the CFC in D and R as
      well; when the contact has ended (I) the set-point is blended from the one held at the pause
      to the live one through the moving average, so the feed-forward f_d of (3.22) does not step
      (:meth:`contact_update` uses it in I).

    docs/hybrid_force_control.md has the variants tried and their figures.
    """

    def __init__(self, T_MA: float, dt: float):
        self.dt = dt
        self.average = MovingAverage(T_MA, dt)
        self.weight = 0.0                       # share of the filtered set-point, 0..1
        self.share = 1.0                        # share of the contact force handed over (contact_update)
        self.paused = False                     # the CFC paused in the last period (run)
        self.bias = LowPass(BIAS_TIME, dt)      # N, a . (f_d - f) - e_F in D (run)
        self.bias.reset(0.0)
        self.bias_step = 0.0                    # N per period of its ramp-out after D
        self.hand_over_gain = 1.0               # 0..1, the integral part's hand-over (run): 0 while saturated
        self.pre_from: np.ndarray | None = None  # the set-point when A began (pre_tension), None outside A
        self.pre_periods = 0                    # periods of A with the pre-contact forces (ramp, then settling)
        self.hold: np.ndarray | None = None     # the set-point held at the pause (A-C)
        self.shift: np.ndarray | None = None    # post_contact_forces - the held set-point, ramped in D

    def set_time_constant(self, T_MA: float) -> None:
        if max(1, int(round(T_MA / self.dt))) != self.average.n:
            last = self.average.y
            self.average = MovingAverage(T_MA, self.dt)
            self.average.reset(last)

    def update(self, state: str, f_d) -> tuple[np.ndarray, bool]:
        """-> (the set-point for the CFC, paused)."""
        f_d = np.asarray(f_d, dtype=float)
        if state in FORCE_CONTROLLED:
            if self.average.y is None or self.weight == 0.0:
                self.average.reset(f_d)             # the set-point at the pause, held
            self.weight = 1.0
            return self.average.y.copy(), True
        if self.weight > 0.0:
            self.weight = max(0.0, self.weight - self.dt / max(self.average.T, self.dt))
        if self.weight == 0.0:
            self.average.reset(None)
            return f_d, False
        filtered = self.average.update(f_d)
        return self.weight * filtered + (1.0 - self.weight) * f_d, False


    @property
    def pre_tensioning(self) -> bool:
        """In A, the set-point's ramp to the pre-contact forces not done (:meth:`pre_tension` wanted)."""
        return self.pre_from is None or self.pre_periods * self.dt < PRE_TENSION_TIME + PRE_TENSION_SETTLE - 1e-9

    def pre_tension(self, AT, e, F_d: float, f_d, f_min, f_max) -> np.ndarray | None:
        """A period of A while :attr:`pre_tensioning`: :func:`pre_contact_forces` (f_from: f_d in A's
        first period; the stage sets :attr:`pre_from` to None outside A)."""
        f_d = np.asarray(f_d, dtype=float)
        if self.pre_from is None:
            self.pre_from, self.pre_periods = f_d.copy(), 0
        return pre_contact_forces(AT, e, F_d, self.pre_from, f_min, f_max)

    def contact_update(self, state: str, f_d, a, bias: float = 0.0, f_pre=None,
                       d=None, f_post=None) -> tuple[np.ndarray, np.ndarray, bool]:
        """Section 5.1.2 with the CFC running in D: desired cable forces f_d (the distribution of the
        wrench with the expected contact force, :func:`expected_contact_wrench`), a of
        :func:`task_force_direction`, bias [N] what the set-point of the error is lowered by along a
        in D, R and I (a . f_err = a . f_d - bias; :meth:`run` gives the bias of a . (f_d - f)
        against the hybrid force controller's error) -> (set-point of the error (3.2), feed-forward
        (3.22), paused).

        - A, given the pre-contact forces f_pre (:meth:`pre_tension`): not paused yet, the set-point
          (error and feed-forward) goes from f_d at A's start to f_pre within PRE_TENSION_TIME and
          stays there for PRE_TENSION_SETTLE; then
          paused and held (running on, the CFC held the contact force x_t pressed at the impact to
          13 N of 150 N for 2 s: IPAnema 3 sweep pose #2), so the contact x_t presses in B adds to
          forces planned for it.
        - A without f_pre, B, C: paused, the set-point of the pause held (thesis).
        - D and R: the error acts on the live f_d (off a it goes there from the one held within
          HAND_OVER_TIME, so the resumed CFC does not step). The feed-forward starts from the one held and
          follows f_d through the moving average of T_MA,HPFC (the thesis's filter "to slow down the
          control loop"), except along a, where it goes to the live f_d within HAND_OVER_TIME: the
          contact force it then presses with is handed over from x_t by :class:`ContactHandOver`
          (the joint command lifts the platform by it over the contact stiffness), so nothing of
          the contact force stays in Δq_CFC after the contact.
        - I: the feed-forward returns to the live set-point through the average as in
          :meth:`update`, again live along a; the error keeps the live set-point of D and R (its
          ramp from the one held completed if R was shorter than HAND_OVER_TIME).
        """
        f_d = np.asarray(f_d, dtype=float)
        if state == IDLE and self.weight == 0.0 and bias == 0.0:   # idle, ramped out: f_d passes, whatever a is
            self.average.reset(None)
            return f_d, f_d, False
        a = np.asarray(a, dtype=float)
        aa = float(a @ a)
        if aa > 0.0:
            d = a / aa if d is None else np.asarray(d, dtype=float)

        def live_along_a(f):
            return f + d * (a @ (f_d - f) - bias) if aa > 0.0 else f

        if state == APPROACH and f_pre is not None and self.pre_from is not None:
            self.pre_periods += 1
            share = min(1.0, self.pre_periods * self.dt / PRE_TENSION_TIME)
            f_set = self.pre_from + share * (np.asarray(f_pre, dtype=float) - self.pre_from)
            self.average.reset(f_set)                   # held from B on (the pause's set-point)
            self.hold = f_set.copy()
            self.weight, self.share = 1.0, 0.0
            return f_set, f_set.copy(), False
        if state in CFC_PAUSED:
            if self.average.y is None or self.weight == 0.0:
                self.average.reset(f_d)
                self.hold = f_d.copy()
            self.weight = 1.0
            self.share = 0.0
            return self.hold.copy(), self.hold.copy(), True
        if state in (CONTACT, RELEASE):
            if self.average.y is None or self.weight == 0.0:  # enabled in contact: no pause before
                self.average.reset(f_d)
                self.hold = f_d.copy()
                self.share = 0.0
            elif self.share == 0.0:                   # resumed after the pause: no shift yet
                self.shift = None
                if f_post is not None and not np.array_equal(f_post, self.hold):
                    # the held set-point's internal tension moved so that its press stays within the
                    # limits (post_contact_forces); the average starts there, the step ramped in below
                    f_post = np.asarray(f_post, dtype=float)
                    self.shift = f_post - self.hold
                    self.hold = f_post.copy()
                    self.average.reset(f_post)
            self.weight = 1.0
            # the hand-over along a ramps in over HAND_OVER_TIME (a step would step θ_d by mm)
            self.share = min(1.0, self.share + self.dt / HAND_OVER_TIME)
            y = self.average.update(f_d).copy()
            if self.shift is not None:
                y -= (1.0 - self.share) * self.shift     # the shift ramped in with the hand-over
                if self.share >= 1.0:
                    self.shift = None
            f_err = y
            if aa > 0.0:
                target = self.hold + self.share * (f_d - self.hold)
                y += d * (a @ (target - y))
                f_err = y + d * (a @ (f_d - y) - bias)          # live along a, less the bias
            return f_err, y, False
        f_ff, _ = self.update(state, f_d)
        f_ff = live_along_a(f_ff)
        return f_ff, f_ff.copy(), False


    def run(self, state: str, f_d, a, controller, f, e_F: float | None = None, f_pre=None,
            d=None, f_post=None) -> tuple[np.ndarray, np.ndarray, bool, float]:
        """:meth:`contact_update` and what it does to the cable force controller (a
        :class:`cdpr_control.control.cable_force_control.CableForceController` with its ``dq_0`` set or None),
        before that controller's update of the period: f the measured cable forces (m,) [N], e_F [N]
        the hybrid force controller's force error F_d - F (None: not known), f_pre the pre-contact
        forces in A (:meth:`pre_tension`) -> (set-point, feed-forward, paused, F_a).

        - In D, given e_F, the error along a is a . (f_d - f) less its bias against e_F, the PT1 of
          BIAS_TIME of a . (f_d - f) - e_F (:attr:`bias`, from 0 at the start of D): fast it is the
          distribution's error as before, steady it is e_F, so the integral part handed over to
          x_t integrates the PID's own error. After D (R, I) the bias ramps out within
          HAND_OVER_TIME (dropped at once, it stepped the drive command by 0.5 mm at the release). Both read the contact force, but a is taken at x_d,
          the measured wrench at the estimated pose, through the distribution's filter: the two
          differ by a few per cent of F_d, and the two integrators on x_t met where their errors
          cancelled (the Mini held 6 N at 5.89 N with x_t standing). On e_F alone (no bias
          estimate) the PID's filtered force in the CFC's fast loop made the IPAnema 3 oscillate
          (docs/hybrid_force_control.md, "Validation sweep").

        - Resuming after the pause it is bumpless: the feedback filter restarts at f and the
          integral part takes the output held at the pause less the proportional part's step.
        - In D and R the integral part along a (the cable forces that change the contact force) is
          handed over to x_t with the CFC's T_i: F_a [N] is the contact force it took out of the
          integrator this period (the hybrid force controller takes F_a / k_t on x_t,
          :meth:`HybridForceControl.absorb`), so the PID (5.3) owns the steady contact force and
          nothing of it stays in Δq_CFC when the contact ends. Not while an output is saturated
          (:attr:`hand_over_gain`, 0 within HAND_OVER_TIME of a saturation, 1 within the same time
          after it): a clamped integral part comes back after the hand-over took it out, which
          only took x_t back against the PID (docs/hybrid_force_control.md, "Session 10").
        """
        a = np.asarray(a, dtype=float)
        bias = float(self.bias.y)
        if state == CONTACT and e_F is not None:
            bias, = self.bias.update_floats((float(a @ (np.asarray(f_d, dtype=float) - np.asarray(f, dtype=float)))
                                             - e_F,))
            self.bias_step = abs(bias) * self.dt / HAND_OVER_TIME
            self.bias.reset(bias)
        elif bias != 0.0:                               # (none to ramp out: the idle period's case)
            # paused: the CFC resumes bumpless from the pause; else ramped out
            bias = 0.0 if state in CFC_PAUSED else math.copysign(max(0.0, abs(bias) - self.bias_step), bias)
            self.bias.reset(bias)
        f_set, f_ff, paused = self.contact_update(state, f_d, a, bias, f_pre, d, f_post)
        c = controller
        if self.paused and not paused and c.dq_0 is not None:     # resume bumpless
            # the PI's output held at the pause (its P part too: after the pre-tension's ramp in A the
            # error is not 0, and resumed on the integral part alone the drive command stepped by
            # 0.27 mm on the floor program) is what the integral part takes over
            c.feedback_filter.reset(f)
            c.pi.integrator = c.pi.output - c.params.K_p * (f_set - f)
        self.paused = paused
        F_a = 0.0
        # no hand-over while an output is saturated (its integral part is clamped, not drained: what
        # the hand-over took out along a came back each period); off and on again over HAND_OVER_TIME
        step = self.dt / HAND_OVER_TIME
        self.hand_over_gain = (max(0.0, self.hand_over_gain - step) if c.pi.saturated.any()
                               else min(1.0, self.hand_over_gain + step))
        aa = float(a @ a) if not paused and state in (CONTACT, RELEASE) else 0.0
        if aa > 0.0 and self.hand_over_gain > 0.0:
            F_a = self.hand_over_gain * min(1.0, self.dt / c.params.T_i) * float(a @ c.pi.integrator)
            c.pi.integrator = c.pi.integrator - F_a * (a / aa if d is None else np.asarray(d, dtype=float))
            # (the cables press with a . f along z_t: a . d = 1)
        return f_set, f_ff, paused, F_a


NO_HAND_OVER = np.zeros(6)          # x_comp while nothing is handed over (shared, read-only)
NO_HAND_OVER.flags.writeable = False


class ContactHandOver:
    """The hand-over offset x_comp of section 5.1.2 (part of :class:`HybridForceStage`).

    The CFC's feed-forward presses along z_t with F_ff = share F_c (:meth:`CFCCoupling.contact_update`
    puts the live f_d along a into it): F_c the expected contact force F_d through the PT1 of the
    force distribution's wrench filter (T_c, so F_ff is what f_d carries), share ramped from 0 over
    HAND_OVER_TIME from the start of D or R (0 while the CFC is paused, A-C), all of F_c in I.
    x_comp = -F_ff / k_t z_t lifts the position offset by what that press pushes the robot, k_t the
    contact stiffness measured in B (else K_p); 0 while the CFC's output is not applied.
    """

    def __init__(self, T_c: float, dt: float):
        self.dt = dt
        self.filter = LowPass(T_c, dt)
        self.share = 1.0

    def set_time_constant(self, T_c: float) -> None:
        self.filter.set_time_constant(T_c)

    def update(self, state: "HPFCState", k_t: float, cfc_on: bool) -> np.ndarray:
        """One period after :meth:`HybridForceControl.update` -> x_comp (6,) [m]; while it is 0 (the
        CFC's output not applied, or no contact force to hand over), :data:`NO_HAND_OVER`."""
        F_c, = self.filter.update_floats((state.F_d if state.state in FORCE_CONTROLLED else 0.0,))
        if state.state in CFC_PAUSED:
            self.share = 0.0
        elif state.state in (CONTACT, RELEASE):
            self.share = min(1.0, self.share + self.dt / HAND_OVER_TIME)
        F_ff = self.share * F_c if state.state in (CONTACT, RELEASE) else (0.0 if state.state in CFC_PAUSED else F_c)
        if not (F_ff != 0.0 and cfc_on and math.isfinite(F_ff) and k_t > 0.0):
            return NO_HAND_OVER
        x_comp = np.zeros(6)
        x_comp[:3] = -F_ff / k_t * state.z_t
        return x_comp


class HybridForceStage:
    """The hybrid position/force control box of Fig. 5.3 as ``ControlLoop`` and the node
    ``hybrid_force_controller`` both run it: :class:`HybridForceControl` ((5.1)-(5.3), Fig. 5.4)
    with the hand-over of section 5.1.2. Per period:

    1. :meth:`take_over` the contact force F_a [N] that the cable force controller's integral part
       handed over in the last period (:meth:`CFCCoupling.run`): x_t moves by F_a / k_t;
    2. :meth:`update`: the state machine and PID of F_d,0 and w, and x_comp of
       :class:`ContactHandOver` -> (HPFCState, the offset x_d,HPFC + x_comp (6,)).

    k_t is the contact stiffness measured in B (``HybridForceControl.k_contact``), else K_p. T_c is
    the force distribution's ``T_wrench_filter`` (the PT1 through which f_d carries the contact).
    """

    def __init__(self, robot, dt: float, params: HPFCParams | None = None, T_c: float = 0.3,
                 enabled: bool = False):
        self.control = HybridForceControl(robot, dt, params, enabled=enabled)
        self.hand_over = ContactHandOver(T_c, dt)

    @property
    def k_t(self) -> float:
        return self.control.k_contact or self.control.params.K_p

    @property
    def takes_over(self) -> bool:
        """Whether :meth:`take_over` acts in this state (D and R): a caller may skip computing F_a."""
        return self.control.state in (CONTACT, RELEASE)

    def take_over(self, F_a: float) -> None:
        """F_a [N] along z_t from the cable force controller's integral part (taken in D and R only,
        :meth:`HybridForceControl.absorb`)."""
        if self.takes_over:
            self.control.absorb(F_a / self.k_t)

    def update(self, F_d0, w, cfc_on: bool, x_d=None, limits=None) -> tuple[HPFCState, np.ndarray]:
        """F_d,0 (3,) [N], the measured wrench w (6,), cfc_on: Δq_CFC applied (in the last period),
        x_d and the distribution's (f_min, f_max) as :meth:`HybridForceControl.update`
        -> (the period's HPFCState, x_d,HPFC + x_comp (6,) [m, rad])."""
        s = self.control.update(F_d0, w, x_d, limits)
        x_comp = self.hand_over.update(s, self.k_t, cfc_on)
        # x + 0.0 is x + np.zeros(6) (the same numbers, -0.0 becoming 0.0 alike) and a new array:
        # the idle state's x is read-only and shared by the periods
        return s, s.x + (0.0 if x_comp is NO_HAND_OVER else x_comp)


class ContactCableForceControl:
    """The cable force control under hybrid force control (section 5.1.2) as ``ControlLoop`` and the
    node ``cable_force_controller`` both run it: :class:`CFCCoupling` around a
    :class:`cdpr_control.control.cable_force_control.CableForceControl` (3.19)-(3.23), with
    a = (A^T(x_d))_F^T z_t (:func:`task_force_direction`, A^T (2.10) of the set-point) and z_t the
    direction of F_d,0 (5.2). Per period :meth:`update` -> Δq_CFC, held while paused (A-C);
    :attr:`F_a` is the contact force the integral part handed over (for :meth:`HybridForceStage.take_over`
    in the next period; 0 while the CFC is off or not calibrated).
    """

    def __init__(self, robot, cfc, T_MA: float, dt: float):
        self.robot = robot
        self.cfc = cfc
        self.coupling = CFCCoupling(T_MA, dt)
        self.z_t = np.array([0.0, 0.0, 1.0])       # task z axis, kept while F_d,0 = 0 (task_axis)
        self._F_d0: bytes | None = None             # F_d,0 (its bytes) of z_t
        self.a_zero = np.zeros(robot.m)             # a without a set-point (never modified)
        self.dq_cfc = np.zeros(robot.m)
        self.F_a = 0.0
        self.contact_saturation = CONTACT_SATURATION   # the CFC's saturation factor in D and R (_saturation)
        self.saturation_factor = 1.0                # the factor applied now
        self._base_params = cfc.params              # the CFC's parameters as set (F_sat,n/p unscaled)
        self._scaled_params = cfc.params            # what _saturation last set

    def _saturation(self, state: str) -> None:
        """The CFC's saturation in D and R: CONTACT_SATURATION times F_sat,n/p; after them back to
        F_sat as far as the PI output held allows (the factor never below what the output needs,
        rounded up to 1 %, so nothing is clipped: a step of the output would step the drives)."""
        c = self.cfc
        if c.params is not self._scaled_params:     # set from outside (the node's parameters): the base
            self._base_params = self._scaled_params = c.params
            self.saturation_factor = 1.0
        base = self._base_params
        if state in (CONTACT, RELEASE):
            k = self.contact_saturation
        elif self.saturation_factor > 1.0:
            u = c.controller.pi.output
            need = max(float(np.max(u)) / base.F_sat_p if base.F_sat_p > 0.0 else 1.0,
                       float(np.max(-u)) / base.F_sat_n if base.F_sat_n > 0.0 else 1.0)
            k = min(self.saturation_factor, max(1.0, math.ceil(100.0 * need) / 100.0))
        else:
            return
        if k != self.saturation_factor:
            self.saturation_factor = k
            self._scaled_params = base if k == 1.0 else replace(base, F_sat_n=k * base.F_sat_n,
                                                                  F_sat_p=k * base.F_sat_p)
            c.set_params(self._scaled_params)

    def needs_setpoint(self, state: str | None) -> bool:
        """Whether :meth:`update` uses x_d: not while idle with the set-point's ramp-out done, where
        the coupling passes f_d through whatever a is (the most frequent case by far)."""
        return (state or IDLE) != IDLE or self.coupling.weight > 0.0

    def update(self, state: str | None, F_d0, x_d, f_d, f, theta, f_min, f_max, F_vec=None) -> np.ndarray:
        """state: the hybrid force controller's (None: none, taken as idle); F_d,0 (3,) [N] and x_d
        (6,) of the period, None where there is none (then a = 0: nothing handed over); f_d, f,
        theta, f_min, f_max as :meth:`CableForceControl.update`; F_vec (3,) [N] the hybrid force
        controller's contact force (``HPFCState.F_vec``; None: the error along a stays on f_d, see
        :meth:`CFCCoupling.run`) -> Δq_CFC (m,) [m]."""
        state = state or IDLE
        # idle with the set-point's ramp-out done: the CFC's own integral part, internal where
        # CFCParams.internal_integral is on (not in A-D, R: there it carries the contact's hand-over)
        x_internal = None if self.needs_setpoint(state) else x_d
        if F_d0 is not None:
            F_d0 = np.asarray(F_d0, dtype=float)
            key = F_d0.tobytes()
            if key != self._F_d0:                   # the same F_d,0 has the same axis
                self.z_t, self._F_d0 = task_axis(F_d0, self.z_t), key
        a, e, f_pre, f_post = self.a_zero, None, None, None
        if F_d0 is not None and x_d is not None and self.needs_setpoint(state):
            AT, = kernels.inverse_kinematics_fields(self.robot, x_d, "AT")   # (2.10) at x_d
            a = task_force_direction(AT, self.z_t)
            e = contact_response(AT, self.cfc.stiffness(f_d, theta), self.z_t)
            if not np.all(np.isfinite(e)):
                e = None
            if state == APPROACH and self.cfc.enabled and self.coupling.pre_tensioning and e is not None:
                f_pre = self.coupling.pre_tension(AT, e, float(self.z_t @ F_d0), f_d, f_min, f_max)
            if (state in (CONTACT, RELEASE) and self.coupling.paused and e is not None and self.cfc.enabled
                    and self.coupling.hold is not None):
                f_post = post_contact_forces(AT, e, float(self.z_t @ F_d0), self.coupling.hold, f_min, f_max)
        if state != APPROACH:
            self.coupling.pre_from = None                # the next A starts from its own f_d
        e_F = None
        if state == CONTACT and F_d0 is not None and F_vec is not None:     # (run reads it in D only)
            F_vec = np.asarray(F_vec, dtype=float)
            e_F = float(self.z_t @ (F_d0 - F_vec)) if F_vec.shape == (3,) and np.all(np.isfinite(F_vec)) else None
        cfc = self.cfc
        f_set, f_ff, paused, F_a = self.coupling.run(state, f_d, a, cfc.controller, f, e_F, f_pre, e, f_post)
        if self.needs_setpoint(state):
            # no set-point above f_max (2.39) reaches the drives: where the wrench with the expected
            # contact has no solution within the limits the distribution returns its least-violating
            # forces (section 3.6.2), and the coupling's live share along a and its bias move the
            # set-point further (Mini #25, seed 2: 2.4 N above f_max); clipped here, as the force
            # set-point clips them while a user guides. Not at f_min: the coupling plans the contact
            # with set-points there on purpose, and clipped, the feed-forward no longer balanced the
            # wrench (the floor program's drive command stepped 0.35 mm; docs/hybrid_force_control.md,
            # "Session 13")
            f_set, f_ff = np.minimum(f_set, f_max), np.minimum(f_ff, f_max)
        self.F_a = F_a if cfc.enabled and cfc.controller.dq_0 is not None else 0.0
        if not paused:                               # held during contact establishment
            self._saturation(state)
            self.dq_cfc = cfc.update(f_set, f, theta, f_min, f_max, f_ff, x_d=x_internal)
        self.f_set, self.f_ff, self.paused = f_set, f_ff, paused
        return self.dq_cfc


def _pose_text(x_d) -> str:
    return "[" + " ".join(f"{v:.4g}" for v in np.asarray(x_d, dtype=float).tolist()) + "]" if x_d is not None else "[?]"


def refusal_message(s: HPFCState, x_d, F_min: float) -> str:
    """Why contact is refused (:attr:`HPFCState.refused`): F_d asked, the capacity, the pose, what is left."""
    return (f"contact refused: F_d {s.F_d_requested:.4g} N asked, the contact capacity of the pose {_pose_text(x_d)} "
            f"is {s.capacity:.4g} N and leaves {s.capacity / (1.0 + CAPACITY_OVERSHOOT):.4g} N to regulate, below "
            f"the smallest force the controller regulates, {F_min:.4g} N (F_th / {1.0 - CAPACITY_OVERSHOOT:g})")


class ContactDiagnostics:
    """What the node ``hybrid_force_controller`` reports on ``/diagnostics`` each period: (level,
    message, values) or None (nothing to publish).

    The level and the *reason* (the state, x_t saturated, F_d limited to the pose's capacity,
    contact refused) decide a report: a change of either is published at once. While F_d is limited
    (or refused) and x_d moves, the message's numbers (F_d asked, the capacity, the pose, the force
    regulated) change every period; they are published at most every ``repeat`` s (the latest ones;
    until session 12 each period: the report flooded /diagnostics). The values (F, F_d, x_t) are
    those of the period published."""

    def __init__(self, repeat: float = DIAGNOSTICS_REPEAT):
        self.repeat = repeat
        self.key: tuple | None = None            # (level, reason) last published
        self.message: str | None = None          # the message last published
        self.t_last = -math.inf                  # s, when

    def update(self, s: HPFCState, x_d, t: float, F_min: float) -> tuple[int, str, dict] | None:
        """The period's state s, pose set-point x_d (6,) (None: not known), time t [s] and the smallest
        force regulated (:meth:`HybridForceControl.minimum_contact_force`) -> a report or None."""
        level = WARN if s.saturated else OK
        reason = f"state {s.state}: {STATE_NAMES[s.state]}" + (", x_t saturated" if s.saturated else "")
        limited = not math.isnan(s.F_d_requested)
        if s.refused:
            level, reason = ERROR, reason + ", contact refused: the pose's capacity is below the smallest force regulated"
        elif limited:
            level, reason = WARN, reason + ", F_d limited to the pose's contact capacity"
        key = (level, reason)
        if key == self.key and (not limited or t - self.t_last < self.repeat - 1e-9):
            return None                          # (the numbers are formatted only for a report)
        message = reason
        values = {"F": f"{s.F:.1f}", "F_d": f"{s.F_d:.1f}", "x_t": f"{s.x_t:.4f}"}
        if s.refused:
            message = f"state {s.state}: {STATE_NAMES[s.state]}, " + refusal_message(s, x_d, F_min)
            values.update(F_d_requested=f"{s.F_d_requested:.4g}", capacity=f"{s.capacity:.4g}", F_min=f"{F_min:.4g}")
        elif limited:
            message = (f"state {s.state}: {STATE_NAMES[s.state]}" + (", x_t saturated" if s.saturated else "")
                       + f", F_d {s.F_d_requested:.4g} N beyond the contact capacity {s.capacity:.4g} N of the pose "
                       f"{_pose_text(x_d)}: regulating {s.F_d:.4g} N")
            values.update(F_d_requested=f"{s.F_d_requested:.4g}", capacity=f"{s.capacity:.4g}")
        if key == self.key and message == self.message:
            return None
        self.key, self.message, self.t_last = key, message, t
        return level, message, values


def format_state(controller: str, state: str) -> str:
    """The ``controller`` field of the HPFC's ControllerState: ``<name>:<state>``."""
    return f"{controller}:{state}"


def parse_state(controller_field: str) -> str | None:
    """The state letter of a ``<name>:<state>`` controller field, None when it carries none."""
    _, sep, state = controller_field.rpartition(":")
    return state if sep and state in STATES else None

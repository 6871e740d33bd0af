"""Joint command: the drive set-point of Fig. 3.4 and (5.10).

    θ_d = IK{x_d + x_OSPC + x_LC + x_HPFC} - Δq_CFC     (x_d = x_d,Adm while hand guiding)

Δq_CFC (3.23) is the elongation the cable force controller commands beyond the encoder
calibration's pre-tension, so the winch is shortened by it. The thesis prints (5.1) and (5.10)
with "+ Δq_d,CFC"; with its own Δq = q - θ > 0 under tension (2.24) only the minus is consistent
(more force needs a shorter cable), so the code departs from the printed sign (docs/control.md). The IK-only reference control of
section 2.3.2 is the same with every offset and Δq_CFC zero.

The command is never NaN: a non-finite result, or a holding fault from the safety monitor, holds
θ_d; and θ_d moves at most v_max per second per cable (the drives' rated cable velocity), so
switching controllers or a jump in an input never commands a step. A hold brakes on the path, as a
CNC does: the cable velocities of the last period are scaled down together (their ratio, the
direction of the path in joint space, is kept) at ``a_brake`` [m/s^2] until θ_d stands, so a hold
while moving is no velocity step either; the cables keep the tension of the last command.

A tripped force watch (:class:`cdpr_control.control.safety.ForceWatch`) holds differently: the last command
is what drove the forces away, so θ_d goes, at most v_max per second per cable, to the watch's safe
command θ_d = IK(x_safe + offset_safe) - Δq_CFC,safe - Δq_hold (the set-point where it tripped, the
controller outputs of the last moment the forces followed within their limits) and stays there:
the last safe pose at the force set-point's tension f_d,safe. Δq_hold = Δq_T + Δq_D, two terms of the
measured forces f through the linear stiffness k = k_spec / l_t (2.15):

* Δq_T restores the internal tension of f_d,safe when the plant has changed since (cables that
  settled under an overload, a push): an integral of the internal force error, f_d,safe - f
  low-pass filtered over ``T_HOLD_FILTER`` and projected onto the null space of A^T(x_safe) (the
  internal forces, which move no pose: its wrench part, sensor errors and the model's, would only
  move the platform), with reset time ``T_HOLD``. It integrates only while the platform stands
  (the wrench part of that error, |A^T (f_d,safe - f)| over the forces, within ``f_min``: a ringing
  platform's forces are no tension to restore; with slack cables their internal part points
  anywhere) and no filtered force is above f_max (an overload is a push, not a tension to restore),
  bounded to the elongation of ``HOLD_RANGES`` force ranges (a settled cable needs more than one:
  the Mini's at cuboid_mini's corner 6 mm after 900 N then 500 N).
* Δq_D damps the platform: Δq_D = K_D (f_slow - f) / k, f_slow the forces low-pass filtered over
  ``T_HOLD_WASHOUT``, a proportional force feedback through a washout (zero at rest, so it moves
  no set-point; a sustained push washes out instead of paying the cables out). A held command
  alone leaves the platform ringing on slack cables after a push for ~100 ms (the Mini, nominal
  plant); drives paying out a cable whose force rises absorb that energy. K_D
  (:func:`hold_damping`) is ``HOLD_DAMPING`` or less, so that the loop K_D G_a(s) washout(s) keeps a
  12 dB gain margin with the robot's drive (3.10)/(5.11) and its dead time (the Mini: 1.5, the
  IPAnema 3: 0.26).

With the force error's integral at 1 / T_HOLD = 20 rad/s and the damping's crossover below the
drives' phase crossover, the hold is stable whatever made the controllers diverge
(tests/control/test_joint_command_hold.py checks the margins of both robots by the stability
analysis of section 3.4). Released, the hold keeps Δq_T (the plant's cables stay as they settled)
as an offset of every later command, and θ_d goes from the held command to the controllers' along
the start ramp's cosine over ``START_RAMP`` (no step: dropping Δq_T at once slackened the settled
cables again and tripped the watch anew).
"""
from __future__ import annotations

import numpy as np

from cdpr_control import kernels
from cdpr_control.control.bumpless import START_RAMP, StartRamp
from cdpr_control.control.safety import all_finite
from cdpr_control.model.cable import total_free_length
from cdpr_control.control.filters import LowPass

A_BRAKE = 5.0   # m/s^2: default deceleration of θ_d in a hold (braking on the path)
# the force-watch hold (module docstring); measured on the Mini's pushes (docs/faults.md, tests/faults/test_faults_pushes.py)
T_HOLD = 0.05           # s, reset time of the hold's tension integral Δq_T
T_HOLD_FILTER = 0.005   # s, PT1 of the forces it integrates
T_HOLD_WASHOUT = 0.05   # s, washout of the hold's force damping Δq_D
HOLD_DAMPING = 1.5      # -, largest gain K_D of the force damping
# -, K_D |G_a washout| at the phase crossover at most: a 12 dB gain margin of the single-cable model.
# 6 dB (K_D 0.52 on the IPAnema 3) held the IPAnema 3 in a growing oscillation after OSPC x100
# (tests/control/test_force_watch.py): the eight cables' feedback on one platform has more gain
# than one cable's; 0.4 held, 0.26 (12 dB) leaves it a factor 1.5 of it
HOLD_GAIN_MARGIN = 0.25
HOLD_RANGES = 10.0      # -, bound of Δq_T: the elongation of this many force ranges (f_max - f_min)


class JointCommand:
    def __init__(self, robot, dt: float, v_max: float | None = None, a_brake: float = A_BRAKE):
        self.robot = robot
        self.dt = dt
        self.v_max = robot.drive.v_max if v_max is None else v_max
        self.a_brake = a_brake
        self.theta_d: np.ndarray | None = None
        self.velocity = np.zeros(robot.m)      # θ̇_d of the last period [m/s]
        self.no_dq = np.zeros(robot.m)         # Δq_CFC when none is given (q - 0 = q)
        self.held = False
        self.dq_hold = np.zeros(robot.m)       # the force-watch hold's correction Δq_T + Δq_D [m]
        self.dq_tension = np.zeros(robot.m)    # its tension integral Δq_T [m]
        self.dq_kept: np.ndarray | None = None  # Δq_T kept after a released hold [m] (None: none)
        self.K_D = hold_damping(robot, dt)
        self._hold_filter = LowPass(T_HOLD_FILTER, dt)
        self._hold_slow = LowPass(T_HOLD_WASHOUT, dt)
        self._watch_hold = False               # the last period held for the force watch
        self._start: np.ndarray | None = None  # θ at power-on while the start ramp runs
        self._gap: np.ndarray | None = None    # θ_0 minus the first target, ramped out
        self._ramp = StartRamp(0.0, dt)
        kernels.warm_up(robot)               # the compiled IK and period loaded now, not in the first period

    def reset(self, theta, ramp_time: float = 0.0) -> None:
        """Start from the measured cable lengths θ, so that enabling the command does not jump.

        ``ramp_time`` [s]: the start ramp (0: none; the loop and the node give ``start_ramp``,
        default :data:`cdpr_control.control.bumpless.START_RAMP`). At power-on the plant holds the tension it was left with,
        which differs from what the controllers command by the model's errors (at a border pose of
        the Mini's default plant a cable 20 N from its set-point); rate-limited alone, the command
        closes that gap in a few periods, a force step that overshoots beyond f_max or slackens a
        cable. Over the ramp θ_d = target + (1 - s) (θ_0 - target_0), s rising as a cosine from 0 to
        1 and target_0 the first period's target, so the drives take the controllers' command over
        smoothly."""
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.robot.m,) or not np.all(np.isfinite(theta)):
            raise ValueError(f"reset needs {self.robot.m} finite cable lengths, got {theta}")
        if not (np.isfinite(ramp_time) and ramp_time >= 0.0):
            raise ValueError(f"ramp_time must be a finite duration >= 0 s, got {ramp_time}")
        self.theta_d = theta.copy()
        self.velocity = np.zeros(self.robot.m)
        self._ramp = StartRamp(ramp_time, self.dt)
        self._start = theta.copy() if self._ramp.running else None
        self._gap = None

    @property
    def starting(self) -> bool:
        """The start ramp of :meth:`reset` is still running."""
        return self._start is not None

    def _ramped(self, target: np.ndarray) -> np.ndarray:
        """The start ramp's θ_d this period: the target plus what is left of the first period's gap
        θ_0 - target (see :meth:`reset`). Only the gap is ramped, so what the controllers change
        during the ramp (the cable force controller's own ramped set-point) passes at once."""
        if self._gap is None:
            self._gap = self._start - target
        theta = target + (1.0 - self._ramp.share()) * self._gap
        if not self._ramp.running:
            self._start = self._gap = None
        return theta

    def target(self, x_d, offsets=(), dq_cfc=None) -> np.ndarray:
        """θ_d before rate limiting: IK of the offset set-point minus Δq_CFC (5.10)."""
        q = kernels.cable_lengths(self.robot, self._offset_pose(x_d, offsets))
        return q if dq_cfc is None else q - dq_cfc

    @staticmethod
    def _offset_pose(x_d, offsets) -> np.ndarray:
        """x_d + Σ offsets, the argument of the IK in (5.10)."""
        x = np.array(x_d, dtype=float)
        for offset in offsets:
            x += offset
        return x

    def update(self, x_d, offsets=(), dq_cfc=None, hold: bool = False, safe=None, f=None) -> np.ndarray:
        """One period: the rate-limited θ_d, or braking to a stand when holding or the target is
        invalid; with ``safe`` = (x_safe, offset_safe, Δq_CFC,safe, f_d,safe) (a tripped force watch,
        :attr:`cdpr_control.control.safety.ForceWatch.safe`) θ_d rate-limited to their target instead, the
        measured forces f (m,) [N] restoring f_d,safe."""
        if self.theta_d is None:
            raise RuntimeError("JointCommand.update before reset(theta)")
        if safe is not None:
            x_safe, offset_safe, dq_safe, f_safe = safe
            if not self._watch_hold and self.dq_kept is not None:   # a hold again: Δq_T goes on from the kept one
                self.dq_tension, self.dq_kept = self.dq_kept, None
                self.dq_hold = self.dq_tension.copy()
            self._watch_hold = True
            self._restore_tension(x_safe, f_safe, f)
            return self._return_to(self.target(x_safe, [offset_safe], dq_safe + self.dq_hold))
        if self._watch_hold:
            self._release()
        if self.dq_kept is not None:
            dq_cfc = (self.no_dq if dq_cfc is None else dq_cfc) + self.dq_kept
        if self._start is not None and not hold:
            return self._starting_period(x_d, offsets, dq_cfc)
        if not hold and len(offsets) == 1 and dq_cfc is not None:
            period = joint_command_period(self.robot, x_d, offsets[0], dq_cfc, self.theta_d, float(self.v_max * self.dt),
                                          float(self.dt))
            if period is not None:
                self.held = False
                self.theta_d, self.velocity = period
                return self.theta_d.copy()
        delta = None if hold else self._step(x_d, offsets, dq_cfc)
        self.held = delta is None
        if self.held:
            delta = self.brake() * self.dt
        self.velocity = delta / self.dt
        self.theta_d = self.theta_d + delta
        return self.theta_d.copy()

    def _starting_period(self, x_d, offsets, dq_cfc) -> np.ndarray:
        """A period of the start ramp: θ_d towards the ramped target, rate-limited; braking if the
        target is not finite."""
        target = self.target(x_d, offsets, dq_cfc)
        if not all_finite(target.tolist()):
            return self.update(None, hold=True)
        return self._move_towards(self._ramped(target), held=False)

    def _restore_tension(self, x_safe, f_safe, f) -> None:
        """One period of Δq_hold = Δq_T + Δq_D (module docstring) from the measured forces f (m,)
        [N] and the set-point's f_d,safe (m,) at x_safe; f not finite or f_d,safe unknown: unchanged."""
        if f_safe is None or f is None:
            return
        f = np.asarray(f, dtype=float)
        if not all_finite(f.tolist()):
            return
        c = self.robot.cable
        k = c.k_spec_nominal / total_free_length(self.robot, self.theta_d)      # (2.15)
        f_lp = self._hold_filter.update(f)
        error = f_safe - f_lp
        AT = kernels.inverse_kinematics(self.robot, x_safe).AT
        wrench = AT @ error
        standing = float(np.linalg.norm(wrench[:3])) <= float(np.max(c.f_min))
        if standing and not np.any(f_lp > c.f_max):
            internal = error - AT.T @ np.linalg.solve(AT @ AT.T, wrench)          # the null space of A^T
            bound = HOLD_RANGES * (c.f_max - c.f_min) / k
            self.dq_tension = np.clip(self.dq_tension + self.dt / T_HOLD * internal / k, -bound, bound)
        damping = self.K_D * (self._hold_slow.update(f) - f) / k                  # Δq_D: the washout
        self.dq_hold = self.dq_tension + damping

    def _release(self) -> None:
        """The force watch released its hold: Δq_T kept as an offset of every later command, the
        damping dropped, θ_d ramped from the held command to the controllers' over START_RAMP."""
        self.dq_kept = self.dq_tension.copy() if self.dq_tension.any() else None
        self.dq_tension = np.zeros(self.robot.m)
        self.dq_hold = np.zeros(self.robot.m)
        self._hold_filter.reset()
        self._hold_slow.reset()
        self._watch_hold = False
        self._ramp = StartRamp(START_RAMP, self.dt)
        self._start = self.theta_d.copy() if self._ramp.running else None
        self._gap = None

    def _return_to(self, theta_safe: np.ndarray) -> np.ndarray:
        """θ_d towards theta_safe at most v_max dt per cable (a held period); braking as :meth:`brake`
        if theta_safe is not finite."""
        if not all_finite(theta_safe.tolist()):
            return self.update(None, hold=True)
        return self._move_towards(theta_safe, held=True)

    def _move_towards(self, theta: np.ndarray, held: bool) -> np.ndarray:
        """One period of θ_d towards θ, at most v_max dt per cable."""
        step = self.v_max * self.dt
        delta = np.minimum(np.maximum(theta - self.theta_d, -step), step)
        self.held = held
        self.velocity = delta / self.dt
        self.theta_d = self.theta_d + delta
        return self.theta_d.copy()

    def _step(self, x_d, offsets, dq_cfc) -> np.ndarray | None:
        """The change of θ_d towards the target, at most v_max dt per cable; None if the target is not finite."""
        return joint_command_step(self.robot, self._offset_pose(x_d, offsets), self.no_dq if dq_cfc is None else dq_cfc,
                                  self.theta_d, self.v_max * self.dt)

    def brake(self) -> np.ndarray:
        """θ̇_d of a braking period: the last one scaled so its largest entry drops by a_brake dt."""
        speed = float(np.abs(self.velocity).max())
        if speed == 0.0:
            return self.velocity
        return self.velocity * (max(speed - self.a_brake * self.dt, 0.0) / speed)


def hold_damping(robot, dt: float) -> float:
    """K_D of the hold's force damping (module docstring): HOLD_DAMPING, or less so that
    K_D |G_a(jω) W(jω)| <= HOLD_GAIN_MARGIN where the phase of G_a W first reaches -180 deg, G_a the
    drive (3.10) or (5.11) with its dead time and half a period of zero-order hold (as the
    stability analysis of section 3.4 models it), W(s) = T s / (1 + T s) the washout of T_HOLD_WASHOUT.
    The phase crossover by bisection on the phase, which falls monotonically."""
    d = robot.drive
    delay = d.T_d + 0.5 * dt

    def response(w: float) -> complex:
        s = 1j * w
        G = 1.0 / (1.0 + d.T_1 * s) if d.model == "pt1_deadtime" else 1.0 / (1.0 + 2.0 * d.zeta * d.T_w * s + (d.T_w * s) ** 2)
        return G * T_HOLD_WASHOUT * s / (1.0 + T_HOLD_WASHOUT * s)

    def phase(w: float) -> float:        # unwrapped: the rational part's angle (in (-pi, pi/2)) minus the delay's
        return float(np.angle(response(w))) - w * delay

    lo, hi = 1.0, 1e6                    # rad/s: phase(lo) > -pi; beyond hi the drive's gain is negligible
    if phase(hi) > -np.pi:
        return HOLD_DAMPING
    for _ in range(200):
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if phase(mid) > -np.pi else (lo, mid)
    return min(HOLD_DAMPING, HOLD_GAIN_MARGIN / abs(response(hi)))


def _joint_command_step(robot, x, dq_cfc, theta_d, step: float) -> np.ndarray | None:
    """The change of θ_d towards the target IK(x) - Δq_CFC (5.10), at most ±step per cable; None if
    the target is not finite."""
    target = kernels.cable_lengths.reference(robot, x) - dq_cfc
    if not all_finite(target.tolist()):
        return None
    # np.minimum/np.maximum: np.clip's dispatch costs more than the arithmetic at 1 kHz
    return np.minimum(np.maximum(target - theta_d, -step), step)


def _joint_command_period(robot, x_d, offset, dq_cfc, theta_d, step: float, dt: float):
    """(θ_d, θ̇_d) of the next period with one offset: θ_d + the step towards IK(x_d + offset) -
    Δq_CFC; None if the target is not finite."""
    delta = _joint_command_step(robot, JointCommand._offset_pose(x_d, [offset]), dq_cfc, theta_d, step)
    return None if delta is None else (theta_d + delta, delta / dt)


joint_command_step = kernels.law("joint_command_step", _joint_command_step, kernels.joint_command_step)
joint_command_period = kernels.law("joint_command_period", _joint_command_period, kernels.compiled_joint_command_period)

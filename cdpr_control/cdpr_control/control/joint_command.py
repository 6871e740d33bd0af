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
controller outputs of the last moment the forces followed within their limits) and stays there.
Δq_hold restores that moment's internal tension when the plant has changed since (cables that
settled under an overload, a push): a pure integral on the force error f_d,safe - f, low-pass
filtered over ``T_HOLD_FILTER`` so that a ringing platform does not feed it and projected onto the
null space of A^T (the internal forces, which move no pose: its wrench part, sensor errors and the
model's, would only move the platform), with reset time ``T_HOLD`` through the linear stiffness
k_spec / l_t (2.15), bounded to the elongation of the force range, and paused while a filtered force
is above f_max (an overload is a push or the oscillation itself, not a tension to restore).
Its crossover, 1 / T_HOLD = 4 rad/s, is far below the drives' bandwidth, so it is stable whatever
made the controllers diverge.
"""
from __future__ import annotations

import numpy as np

from cdpr_control import kernels
from cdpr_control.control.bumpless import StartRamp
from cdpr_control.control.safety import all_finite
from cdpr_control.model.cable import total_free_length
from cdpr_control.control.filters import LowPass

A_BRAKE = 5.0   # m/s^2: default deceleration of θ_d in a hold (braking on the path)
T_HOLD = 0.25         # s, reset time of the force-watch hold's tension integral
T_HOLD_FILTER = 0.05  # s, PT1 of the forces it integrates


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
        self.dq_hold = np.zeros(robot.m)       # the force-watch hold's tension correction [m]
        self._hold_filter = LowPass(T_HOLD_FILTER, dt)
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
            self._restore_tension(x_safe, f_safe, f)
            return self._return_to(self.target(x_safe, [offset_safe], dq_safe + self.dq_hold))
        if self._hold_filter.y is not None:    # (released: the next hold starts afresh)
            self.dq_hold = np.zeros(self.robot.m)
            self._hold_filter.reset()
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
        """One period of Δq_hold: dt / T_HOLD of the filtered internal force error as elongation (2.15)."""
        if f_safe is None or f is None or not all_finite(np.asarray(f, dtype=float).tolist()):
            return
        c = self.robot.cable
        f_lp = self._hold_filter.update(np.asarray(f, dtype=float))
        if np.any(f_lp > c.f_max):
            return
        error = f_safe - f_lp
        AT = kernels.inverse_kinematics(self.robot, x_safe).AT
        internal = error - AT.T @ np.linalg.solve(AT @ AT.T, AT @ error)       # the null space of A^T
        k = c.k_spec_nominal / total_free_length(self.robot, self.theta_d)      # (2.15)
        bound = (c.f_max - c.f_min) / k
        self.dq_hold = np.clip(self.dq_hold + self.dt / T_HOLD * internal / k, -bound, bound)

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

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
"""
from __future__ import annotations

import numpy as np

from cdpr_control import kernels
from cdpr_control.kernels.model import joint_command_period
from cdpr_control.kernels.robot_data import robot_data, vector
from cdpr_control.control.safety import all_finite

A_BRAKE = 5.0   # m/s^2: default deceleration of θ_d in a hold (braking on the path)


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
        kernels.warm_up(robot)               # the compiled IK loaded now, not in the first period
        if kernels.ENABLED:                  # and the compiled period (kernels.model.joint_command_period)
            x, f = np.zeros(6), np.zeros(robot.m)
            joint_command_period(x, x, *self._robot_arrays(), f, f, 1e-3, 1e-3, np.empty(robot.m), np.empty(robot.m))

    def _robot_arrays(self) -> tuple:
        d = robot_data(self.robot)
        return d.a, d.b, d.R_A, d.r_p, d.pulleys

    def reset(self, theta) -> None:
        """Start from the measured cable lengths θ, so that enabling the command does not jump."""
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.robot.m,) or not np.all(np.isfinite(theta)):
            raise ValueError(f"reset needs {self.robot.m} finite cable lengths, got {theta}")
        self.theta_d = theta.copy()
        self.velocity = np.zeros(self.robot.m)

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

    def update(self, x_d, offsets=(), dq_cfc=None, hold: bool = False) -> np.ndarray:
        """One period: the rate-limited θ_d, or braking to a stand when holding or the target is invalid."""
        if self.theta_d is None:
            raise RuntimeError("JointCommand.update before reset(theta)")
        if not hold and kernels.ENABLED and len(offsets) == 1 and dq_cfc is not None:
            theta_d = self._period(x_d, offsets[0], dq_cfc)
            if theta_d is not None:
                return theta_d
        delta = None if hold else self._step(x_d, offsets, dq_cfc)
        self.held = delta is None
        if self.held:
            delta = self.brake() * self.dt
        self.velocity = delta / self.dt
        self.theta_d = self.theta_d + delta
        return self.theta_d.copy()

    def _period(self, x_d, offset, dq_cfc) -> np.ndarray | None:
        """:meth:`update` of one offset in one compiled call (kernels.model.joint_command_period, the same numbers); None
        where it does not apply (shapes to broadcast, or a target that is not finite: :meth:`update`
        then takes its general path)."""
        m = self.robot.m
        x_d, offset, dq_cfc, theta_d = vector(x_d), vector(offset), vector(dq_cfc), vector(self.theta_d)
        if x_d.shape != (6,) or offset.shape != (6,) or dq_cfc.shape != (m,) or theta_d.shape != (m,):
            return None
        theta_next, velocity = np.empty(m), np.empty(m)
        if not joint_command_period(x_d, offset, *self._robot_arrays(), dq_cfc, theta_d, float(self.v_max * self.dt),
                                    float(self.dt), theta_next, velocity):
            return None
        self.held = False
        self.velocity, self.theta_d = velocity, theta_next
        return theta_next.copy()

    def _step(self, x_d, offsets, dq_cfc) -> np.ndarray | None:
        """The change of θ_d towards the target, at most v_max dt per cable; None if the target is not finite."""
        step = self.v_max * self.dt
        if kernels.ENABLED:           # the same in one compiled call
            return kernels.joint_command_step(self.robot, self._offset_pose(x_d, offsets),
                                              self.no_dq if dq_cfc is None else dq_cfc, self.theta_d, step)
        target = self.target(x_d, offsets, dq_cfc)
        if not all_finite(target.tolist()):
            return None
        # np.minimum/np.maximum: np.clip's dispatch costs more than the arithmetic at 1 kHz
        return np.minimum(np.maximum(target - self.theta_d, -step), step)

    def brake(self) -> np.ndarray:
        """θ̇_d of a braking period: the last one scaled so its largest entry drops by a_brake dt."""
        speed = float(np.abs(self.velocity).max())
        if speed == 0.0:
            return self.velocity
        return self.velocity * (max(speed - self.a_brake * self.dt, 0.0) / speed)

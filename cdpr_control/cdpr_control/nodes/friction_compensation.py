"""Node ``friction_compensation``: cable force at the platform from the winch sensors (3.40)-(3.44).

Subscribes ``winch/state`` (θ, θ̇ and the sensor forces F_s in ``effort``), ``setpoint`` (x_d, for
the wrap angle β_np of the swivelling pulley from the inverse kinematics, section 3.7.3) and, when
``velocity_source`` is ``desired``, ``winch/command`` (θ_d); publishes ``cable_forces``
(cdpr_msgs/CableForces: f at the platform with the cable limits).

The thesis drives the friction model with the commanded θ_d, θ̇_d, which run ahead of the cable,
and shifts the Dahl output by 50 ms (section 3.7.3): ``velocity_source = desired`` with
``time_shift = 0.05``. With the encoder values (``measured``, the default here, deterministic in
lockstep) no shift is needed. The friction parameters default to the robot file; ``cdpr identify
friction`` writes a parameter file with identified ones. The computation is
:class:`cdpr_control.control.friction_compensation.FrictionCompensation`.
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import CableForces, OperationalSetpoint
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState

from cdpr_control.control.friction_compensation import FrictionCompensation, FrictionCompensationParams
from cdpr_control import kernels
from cdpr_control.control.params import section
from cdpr_control.control.safety import all_finite

from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.conversions import setpoint_pose
from cdpr_control.ros.parameters import ParameterSet, ParamSpec
from cdpr_control.ros.qos import CONTROL
from cdpr_control.ros.sync import StampSync


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md); the stage's of
    FrictionCompensationParams' field names (section), the friction model the robot file's."""
    fr, d = robot.friction, FrictionCompensationParams()   # the defaults live in the dataclass
    return [
        ParamSpec("enabled", d.enabled, "compensate pulley friction; off = f = f_w (3.40)"),
        ParamSpec("velocity_source", "measured", "θ, θ̇ driving the friction model: measured (encoders) "
                  "or desired (θ_d as in section 3.7.3)", choices=("measured", "desired")),
        ParamSpec("time_shift", d.time_shift, "delay of the Dahl output [s]; the thesis uses 0.05 with desired",
                  range=(0.0, 1.0)),
        ParamSpec("mu", fr.mu.tolist(), "Coulomb coefficient per cable [-] (3.31)"),
        ParamSpec("sigma", fr.sigma.tolist(), "Dahl stiffness per cable [N/m] (3.43)"),
        ParamSpec("F_pv", fr.F_pv.tolist(), "viscous parameter per cable [N s/m] (3.31)"),
    ]


class FrictionCompensationNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("friction_compensation", **kwargs)
        self.stage = None
        # the last two winch commands as they came, (t, θ_d) (None before them): θ̇_d is their
        # difference quotient, computed in the periods that use it (velocity_source desired)
        self._commands: tuple = (None, None)
        self.params = ParameterSet(self, parameters(self.robot), self._validate, self._apply)
        self.publisher = self.create_publisher(CableForces, "cable_forces", CONTROL)
        self.f_min, self.f_max = self.robot.cable.f_min.tolist(), self.robot.cable.f_max.tolist()   # the robot's limits
        self.create_subscription(JointState, "winch/command", self._keep_command, CONTROL, adapted=True)
        self.sync = StampSync(self, {
            "state": (JointState, "winch/state"),
            "setpoint": (OperationalSetpoint, "setpoint"),
        }, primary="state", callback=self._cycle, mode=self.sync_mode, urgent=("state",))   # the command path

    def _validate(self, v: dict) -> None:
        section(FrictionCompensationParams, v).resolved(self.robot)

    def _apply(self, v: dict) -> None:
        self.velocity_source = v["velocity_source"]
        if self.stage is None:
            self.stage = FrictionCompensation(self.robot, self.dt, section(FrictionCompensationParams, v))
        else:
            self.stage.set_params(section(FrictionCompensationParams, v))

    def _keep_command(self, msg: JointState) -> None:
        stamp = msg.header.stamp
        self._commands = (self._commands[1], (stamp.sec + 1e-9 * stamp.nanosec, msg.position))

    @property
    def command(self) -> tuple[float, np.ndarray, np.ndarray] | None:
        """(t, θ_d, θ̇_d) of the last winch command; θ̇_d the difference quotient to the one before
        (zero for the first command or one not later than that)."""
        last, latest = self._commands
        if latest is None:
            return None
        t, position = latest
        theta_d = np.asarray(position, dtype=float)
        if last is None or t <= last[0]:
            return t, theta_d, np.zeros_like(theta_d)
        return t, theta_d, (theta_d - np.asarray(last[1], dtype=float)) / (t - last[0])

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        state = msgs["state"]
        effort = state.effort
        if len(effort) != self.robot.m or not all_finite(effort):
            self.report(DiagnosticStatus.ERROR, "sensor forces missing or non-finite", stamp_ns=t_ns)
            return
        F_s = np.asarray(effort, dtype=float)
        command = self.command if self.velocity_source == "desired" else None
        if command is not None:
            _, theta, thetadot = command
        else:
            theta, thetadot = np.asarray(state.position, dtype=float), np.asarray(state.velocity, dtype=float)
        # β_np (2.6) of x_d: the period's IK of x_d, which the forward kinematics, the force set-point
        # and load compensation take too (kernels.inverse_kinematics_fields)
        beta, = kernels.inverse_kinematics_fields(self.robot, setpoint_pose(msgs["setpoint"]), "beta")
        f = self.stage.update(F_s, theta, thetadot, beta)
        self.publisher.publish(self.message_factory(CableForces)(header=self.header(t_ns), f=f, f_min=self.f_min,
                                                                 f_max=self.f_max))


def main(args=None):
    spin_node(FrictionCompensationNode, args)


if __name__ == "__main__":
    main()

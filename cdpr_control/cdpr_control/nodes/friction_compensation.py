"""Node ``friction_compensation``: cable force at the platform from the winch sensors (3.40)-(3.44).

Subscribes ``winch/state`` (θ, θ̇ and the sensor forces F_s in ``effort``), ``setpoint`` (x_d, for
the wrap angle β_np of the swivelling pulley from the inverse kinematics, section 3.7.3) and, when
``velocity_source`` is ``desired``, ``winch/command`` (θ_d); publishes ``cable_forces``
(cdpr_msgs/CableForces: f at the platform with the cable limits).

f = f_w + F_D (3.44) with f_w from the sensor (3.40) and the Dahl friction F_D (3.43). The thesis
drives the friction model with the commanded θ_d, θ̇_d, which run ahead of the cable, and shifts
the Dahl output by 50 ms (section 3.7.3): ``velocity_source = desired`` with ``time_shift = 0.05``.
With the encoder values (``measured``, the default here, deterministic in lockstep) no shift is
needed. The friction parameters default to the robot file; ``cdpr identify friction`` writes a
parameter file with identified ones.
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import CableForces, OperationalSetpoint
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState

from cdpr_control.friction import PulleyFriction, winch_force_from_sensor
from cdpr_control.kinematics import inverse_kinematics

from .base import CdprNode, spin_node
from .conversions import pose_from_msg
from .parameters import ParameterSet, ParamSpec
from .qos import CONTROL
from .sync import StampSync


class FrictionCompensationNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("friction_compensation", **kwargs)
        fr = self.robot.friction
        specs = [
            ParamSpec("enabled", True, "compensate pulley friction; off = f = f_w (3.40)"),
            ParamSpec("velocity_source", "measured", "θ, θ̇ driving the friction model: measured (encoders) "
                      "or desired (θ_d as in section 3.7.3)", choices=("measured", "desired")),
            ParamSpec("time_shift", 0.0, "delay of the Dahl output [s]; the thesis uses 0.05 with desired",
                      range=(0.0, 1.0)),
            ParamSpec("mu", fr.mu.tolist(), "Coulomb coefficient per cable [-] (3.31)"),
            ParamSpec("sigma", fr.sigma.tolist(), "Dahl stiffness per cable [N/m] (3.43)"),
            ParamSpec("F_pv", fr.F_pv.tolist(), "viscous parameter per cable [N s/m] (3.31)"),
        ]
        self.model: PulleyFriction | None = None
        self.theta_d: tuple[int, np.ndarray] | None = None
        self.params = ParameterSet(self, specs, self._validate, self._apply)
        self.publisher = self.create_publisher(CableForces, "cable_forces", CONTROL)
        self.create_subscription(JointState, "winch/command", self._keep_command, CONTROL)
        self.sync = StampSync(self, {
            "state": (JointState, "winch/state"),
            "setpoint": (OperationalSetpoint, "setpoint"),
        }, primary="state", callback=self._cycle, mode=self.sync_mode)

    def _validate(self, v: dict) -> None:
        m = self.robot.m
        for name in ("mu", "sigma", "F_pv"):
            x = np.asarray(v[name], dtype=float)
            if x.shape != (m,) or not np.all(np.isfinite(x)):
                raise ValueError(f"{name} needs {m} finite values, got {list(v[name])}")
        if np.any(np.asarray(v["mu"]) < 0) or np.any(np.asarray(v["F_pv"]) < 0) or np.any(np.asarray(v["sigma"]) <= 0):
            raise ValueError("friction needs mu >= 0, F_pv >= 0 and sigma > 0")

    def _apply(self, v: dict) -> None:
        self.enabled = v["enabled"]
        self.velocity_source = v["velocity_source"]
        self.shift = int(round(v["time_shift"] / self.dt))
        self.buffer: list[np.ndarray] = []
        self.values = v
        self.model = None                       # rebuilt with the new parameters at the next sample

    def _keep_command(self, msg: JointState) -> None:
        theta_d = np.asarray(msg.position, dtype=float)
        t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        previous = self.theta_d
        thetadot_d = np.zeros_like(theta_d) if previous is None or t <= previous[0] else (theta_d - previous[1]) / (t - previous[0])
        self.theta_d = (t, theta_d, thetadot_d)

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        state = msgs["state"]
        F_s = np.asarray(state.effort, dtype=float)
        m = self.robot.m
        out = CableForces(header=self.header(t_ns), f_min=self.robot.cable.f_min.tolist(),
                          f_max=self.robot.cable.f_max.tolist())
        if F_s.shape != (m,) or not np.all(np.isfinite(F_s)):
            self.report(DiagnosticStatus.ERROR, "sensor forces missing or non-finite", stamp_ns=t_ns)
            return
        f_w = winch_force_from_sensor(F_s, self.robot.sensor.beta_1)           # (3.40)
        if not self.enabled:
            out.f = f_w.tolist()
            self.publisher.publish(out)
            return
        if self.velocity_source == "desired" and self.theta_d is not None:
            _, theta, thetadot = self.theta_d
        else:
            theta, thetadot = np.asarray(state.position, dtype=float), np.asarray(state.velocity, dtype=float)
        if self.model is None:
            v = self.values
            fr = self.robot.friction
            self.model = PulleyFriction(v["mu"], v["sigma"], v["F_pv"], fr.n_pulleys, fr.beta_inner,
                                        self.robot.sensor.beta_1, theta)
        beta = inverse_kinematics(self.robot, pose_from_msg(msgs["setpoint"].pose)).beta
        F_D = self.model.platform_force(F_s, theta, thetadot, beta) - f_w      # (3.43)
        self.buffer.append(F_D)
        if len(self.buffer) > self.shift + 1:
            self.buffer.pop(0)
        out.f = (f_w + self.buffer[0]).tolist()                                # (3.44), shifted
        self.publisher.publish(out)


def main(args=None):
    spin_node(FrictionCompensationNode, args)


if __name__ == "__main__":
    main()

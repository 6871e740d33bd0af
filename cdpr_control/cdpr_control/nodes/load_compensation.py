"""Node ``load_compensation``: online load identification (4.4) and load compensation (4.5)-(4.6), Fig. 4.5.

Subscribes ``setpoint`` (x_d, ẋ_d, ẍ_d), ``cable_forces`` (f at the platform) and ``platform/pose``
(the forward kinematics' x, used with ``acceleration_source: estimated``). Publishes every period,
enabled or not:

- ``load_compensation/state`` (cdpr_msgs/ControllerState): ``output`` = x_d,LC [m, m, m, rad, rad,
  rad], an offset input of the joint command (docs/control.md); ``feedforward`` = C_x w_c before
  the output filter and rate limit; ``reference`` = x_d; ``saturated`` = rate limit active per axis;
  ``enabled`` = the ``enabled`` parameter, or an identified settlement (``settlement_identified``):
  with x_d,LC disabled the output is then the pose offset that shortens the cables by the
  settlement model's s (``settlement_offset``); else zero, and the joint command ramps it out.
- ``load_compensation/payload`` (geometry_msgs/InertiaStamped, frame ``platform``): ``m`` = the
  estimated payload m_c = m̂_p - m_p [kg]; ``com`` = its centre of gravity in the platform frame
  [m] once m_c exceeds ``cog_min_mass`` (before: zero, the platform origin); the inertia entries
  are zero (not identified). The force distribution takes it into its model wrench with its
  ``payload_input`` parameter.

- ``load_compensation/settlement`` (sensor_msgs/JointState, ``position`` = the settlement model's s [m]
  per cable), only where ``settlement_identified`` and the ratio is not zero: the forward kinematics
  lengthens its cables by it (section 4.1.3; cause A of docs/load_compensation.md).

Service ``~/tare`` (std_srvs/Trigger): tare the estimate at a known state (at rest with the payload
``tare_payload`` on, e.g. empty at home after power-on); ``tare_at_start`` does it once by itself.

The computation is :class:`cdpr_control.control.load_compensation.LoadCompensation`.
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import CableForces, ControllerState, OperationalSetpoint
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Inertia, InertiaStamped, PoseStamped
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from cdpr_control.control.load_compensation import (ACCELERATION_SOURCES, OFFSET_MODELS, STIFFNESS_MODELS,
    LoadCompensation, LoadCompensationParams)
from cdpr_control.control.safety import all_finite
from cdpr_control.control.ospc import AXES
from cdpr_control.ros.message_builders import builder

from cdpr_control.control.params import section
from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.conversions import setpoint_from_msg, vector3
from cdpr_control.ros.parameters import ParameterSet, ParamSpec
from cdpr_control.ros.qos import CONTROL
from cdpr_control.ros.sync import StampSync

D = LoadCompensationParams        # the defaults are the library's (one source)
PARAMS = [
    ParamSpec("enabled", D.enabled, "add x_d,LC to the set-point (the identification runs regardless)"),
    ParamSpec("T_filter", D.T_filter, "moving-average window of the mass estimate (4.4) [s] (thesis: 0.24 s); with "
              "acceleration_source estimated the period of the platform's swing where longer (up to 1 s)",
              range=(0.0, 10.0)),
    ParamSpec("time_shift", D.time_shift, "delay of the commanded acceleration in (4.4) [s]", range=(0.0, 0.5)),
    ParamSpec("accel_guard", D.accel_guard, "|ẍ_z - g| below this holds the estimate [m/s^2]", range=(1e-3, 9.81)),
    ParamSpec("acceleration_source", D.acceleration_source, "ẍ_z of (4.4): commanded (time-shifted ẍ_d, thesis) "
              "or estimated (from the forward kinematics' pose)", choices=ACCELERATION_SOURCES),
    ParamSpec("offset_model", D.offset_model, "x_d,LC: secant (the elastic equilibrium at x_d, exact for the cable "
              "model) or tangent (C_x w_c of (4.5)-(4.6))", choices=OFFSET_MODELS),
    ParamSpec("stiffness_model", D.stiffness_model, "tangent model: K_l in K_x (2.22): linear k_spec/l_t (2.15) or "
              "the tangent of the non-linear cable (2.16)-(2.17)", choices=STIFFNESS_MODELS),
    ParamSpec("slack_fraction", D.slack_fraction, "measured cable forces below this share of f_min count as "
              "(partly) slack", range=(0.0, 1.0)),
    ParamSpec("tare_at_start", D.tare_at_start, "tare the estimate once (4.4) is in its final form (its window "
              "and, with the estimated acceleration, the velocity base full; start at a known payload, tare_payload)"),
    ParamSpec("tare_payload", D.tare_payload, "the payload on the platform at a tare (~/tare, tare_at_start) [kg]",
              range=(0.0, 1e4)),
    ParamSpec("platform_mass", D.platform_mass, "the platform's own mass m_p [kg]; 0 = the robot file's",
              range=(0.0, 1e4)),
    ParamSpec("torque", D.torque, "also compensate the moment of the payload at its identified cog"),
    ParamSpec("cog_min_mass", D.cog_min_mass, "payload above which its centre of gravity is identified [kg]",
              range=(0.0, 1e4)),
    ParamSpec("T_output", D.T_output, "PT1 time constant on C_x w_c [s]", range=(0.0, 10.0)),
    ParamSpec("v_max", D.v_max, "rate limit of the translation of x_d,LC [m/s]", range=(0.0, 10.0)),
    ParamSpec("omega_max", D.omega_max, "rate limit of the rotation of x_d,LC [rad/s]", range=(0.0, 10.0)),
    ParamSpec("settlement_ratio", D.settlement_ratio, "cable settlement model (section 4.1.3; `cdpr identify "
              "settlement`): settlement strain per elastic strain of the extra force; 0: off", range=(0.0, 10.0)),
    ParamSpec("settlement_time", D.settlement_time, "time constant of the cable settlement [s]", range=(1e-3, 1e3)),
    ParamSpec("settlement_identified", D.settlement_identified, "the settlement ratio was identified on this robot "
              "(`cdpr identify settlement -o` writes true): its s also lengthens the forward kinematics' cables "
              "(published on load_compensation/settlement), and where x_d,LC is off the output shortens them by it; "
              "false: x_d,LC only"),
]


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md)."""
    return list(PARAMS)


class LoadCompensationNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("load_compensation", **kwargs)
        self.stage: LoadCompensation | None = None
        self.params = ParameterSet(self, parameters(self.robot), self._validate, self._apply)
        self.state_pub = self.create_publisher(ControllerState, "load_compensation/state", CONTROL)
        self.payload_pub = self.create_publisher(InertiaStamped, "load_compensation/payload", CONTROL)
        self.settlement_pub = None       # created at the first identified settlement (none in the default graph)
        self.sync = StampSync(self, {
            "setpoint": (OperationalSetpoint, "setpoint"),
            "f": (CableForces, "cable_forces"),
            "pose": (PoseStamped, "platform/pose"),
        }, primary="f", callback=self._cycle, mode=self.sync_mode)
        self.create_service(Trigger, "~/tare", self._on_tare)

    def _on_tare(self, request, response):
        """Tare the estimate now: it reads the platform plus ``tare_payload`` (at rest, payload known)."""
        offset = self.stage.tare()
        response.success = offset is not None
        response.message = (f"tared: {offset:+.2f} kg removed from the estimate" if response.success
                             else "estimate held or not yet available: not tared")
        return response

    def _validate(self, v: dict) -> None:
        section(LoadCompensationParams, v).validate()

    def _apply(self, v: dict) -> None:
        if self.stage is None:
            self.stage = LoadCompensation(self.robot, self.dt, section(LoadCompensationParams, v))
        else:
            self.stage.set_params(section(LoadCompensationParams, v))

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        sp = msgs["setpoint"]
        x_d, xdot_d, xddot_d = setpoint_from_msg(sp)
        f = np.asarray(msgs["f"].f, dtype=float)
        x = None
        if "pose" in msgs:        # the estimated position: (4.4) takes its z alone (LoadCompensation.identify)
            p = msgs["pose"].pose.position
            x = (p.x, p.y, p.z)
        header = self.header(t_ns)
        lc = self.stage
        reference = x_d.tolist()
        valid = f.shape == (self.robot.m,) and all_finite(reference + xdot_d.tolist() + xddot_d.tolist())
        if valid:
            x_lc = lc.update(x_d, xdot_d, xddot_d, f, x)
        else:
            x_lc = lc.x_lc.copy() if lc.active else np.zeros(6)     # hold: never NaN
        enabled = lc.active
        self.state_pub.publish(self.message_factory(ControllerState)(
            header=header, controller="load_compensation", enabled=enabled, names=list(AXES),
            reference=reference, feedforward=lc.x_target.tolist(), output=x_lc.tolist(),
            saturated=lc.rate_limited.tolist()))
        com = (0.0, 0.0, 0.0) if lc.cog is None else lc.cog
        self.payload_pub.publish(builder(InertiaStamped)(header=self.header(t_ns, "platform"),
                                                         inertia=builder(Inertia)(m=float(lc.m_c), com=vector3(com))))
        if (s := lc.pose_settlement()) is not None:          # identified: for the forward kinematics
            if self.settlement_pub is None:
                self.settlement_pub = self.create_publisher(JointState, "load_compensation/settlement", CONTROL)
            self.settlement_pub.publish(builder(JointState)(header=header, position=s.tolist()))
        if not valid:
            self.report(DiagnosticStatus.ERROR, "invalid input (shape or non-finite): holding", stamp_ns=t_ns)
        elif lc.guarded:
            self.report(DiagnosticStatus.WARN, "estimate held (acceleration near g or invalid wrench)", stamp_ns=t_ns)
        elif (problem := lc.slack_problem()) is not None:
            self.report(DiagnosticStatus.WARN, problem, stamp_ns=t_ns)
        else:
            self.report(DiagnosticStatus.OK, "ok" if lc.params.enabled else (
                "identifying; x_d,LC disabled, the identified cable settlement compensated" if enabled
                else "identifying (compensation disabled)"), stamp_ns=t_ns)


def main(args=None):
    spin_node(LoadCompensationNode, args)


if __name__ == "__main__":
    main()

"""Node ``joint_command``: θ_d = IK{x_d + x_OSPC} - Δq_CFC (Fig. 3.4, (5.10)) to the drives.

Subscribes ``setpoint``, ``ospc/state``, ``cable_force_controller/state`` (synchronised per
period), and for safety ``winch/state``, ``cable_forces`` and ``forward_kinematics/diagnostics``;
publishes ``winch/command`` (sensor_msgs/JointState, position = θ_d [m]) and ``/diagnostics``.

``mode`` switches between the thesis's force control and the IK-only reference control
(section 2.3.2) at run time; x_OSPC and Δq_CFC are blended in and out over ``transfer_time``
(also when a controller reports itself enabled or disabled), and the command is rate-limited to
the drives' v_max. Faults of the safety monitor (non-finite input, position lag, FK not converged, stale
input, and optionally force limits) hold the last safe θ_d; the command is never NaN.
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import CableForces, ControllerState, ForwardKinematicsDiagnostics, OperationalSetpoint
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState

from cdpr_control.bumpless import Blend
from cdpr_control.control_loop import ControlLoopParams
from cdpr_control.joint_command import JointCommand
from cdpr_control.safety import SafetyConfig, SafetyMonitor

from .base import CdprNode, spin_node
from .conversions import pose_from_msg
from .parameters import ParameterSet, ParamSpec
from .qos import CONTROL
from .sync import StampSync, stamp_ns

_S = SafetyConfig()   # the defaults live in the dataclass (one source of truth)
PARAMS = [
    ParamSpec("mode", "force_control", "force_control: θ_d = IK(x_d + x_OSPC) - Δq_CFC; ik_only: θ_d = IK(x_d) (2.3.2)",
              choices=("force_control", "ik_only")),
    ParamSpec("v_max", 0.0, "rate limit of θ_d [m/s]; 0 = the robot's drive v_max", range=(0.0, 100.0)),
    ParamSpec("force_tolerance", _S.force_tolerance, "force beyond [f_min, f_max] tolerated before a fault [N]", range=(0.0, 1e5)),
    ParamSpec("hold_on_force_limit", _S.hold_on_force_limit, "a force-limit fault holds θ_d (else it is only reported)"),
    ParamSpec("max_position_lag", _S.max_position_lag, "position lag |r_d - r| that holds θ_d [m]", range=(0.0, 10.0)),
    ParamSpec("max_orientation_lag", _S.max_orientation_lag, "orientation lag |phi_d - phi| that holds θ_d [rad]", range=(0.0, 3.2)),
    ParamSpec("stale_timeout", _S.stale_timeout, "age of an input that holds θ_d [s]", range=(0.0, 10.0)),
    ParamSpec("transfer_time", ControlLoopParams.transfer_time, "bumpless transfer: x_OSPC and Δq_CFC are "
              "blended in and out over this time on a mode switch or a controller enabled/disabled [s]",
              range=(0.0, 10.0)),
]


class JointCommandNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("joint_command", **kwargs)
        self.names = [f"cable_{i + 1}" for i in range(self.robot.m)]
        self.command = JointCommand(self.robot, self.dt)
        self.blends = {"ospc": Blend(0.0, self.dt), "cfc": Blend(0.0, self.dt)}     # bumpless transfer
        self.monitor = SafetyMonitor()
        self.params = ParameterSet(self, PARAMS, self._validate, self._apply)
        self.latest: dict[str, object] = {}
        for name, msg_type, topic in (("theta", JointState, "winch/state"), ("f", CableForces, "cable_forces"),
                                      ("fk", ForwardKinematicsDiagnostics, "forward_kinematics/diagnostics")):
            self.create_subscription(msg_type, topic, self._keep(name), CONTROL)
        self.publisher = self.create_publisher(JointState, "winch/command", CONTROL)
        self.sync = StampSync(self, {
            "setpoint": (OperationalSetpoint, "setpoint"),
            "ospc": (ControllerState, "ospc/state"),
            "cfc": (ControllerState, "cable_force_controller/state"),
        }, primary="cfc", callback=self._cycle, mode=self.sync_mode)

    def _keep(self, name):
        def keep(msg):
            self.latest[name] = msg
        return keep

    @staticmethod
    def _safety(v: dict) -> SafetyConfig:
        return SafetyConfig(force_tolerance=v["force_tolerance"], max_position_lag=v["max_position_lag"],
                            max_orientation_lag=v["max_orientation_lag"], stale_timeout=v["stale_timeout"],
                            hold_on_force_limit=v["hold_on_force_limit"])

    def _validate(self, v: dict) -> None:
        self._safety(v).validate()

    def _apply(self, v: dict) -> None:
        self.mode = v["mode"]
        self.command.v_max = v["v_max"] or self.robot.drive.v_max
        for blend in self.blends.values():
            blend.set_transfer_time(v["transfer_time"])
        self.monitor = SafetyMonitor(self._safety(v))

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        theta_msg = self.latest.get("theta")
        if theta_msg is None:
            return                                   # no measurement yet: nothing safe to start from
        if self.command.theta_d is None:
            self.command.reset(np.asarray(theta_msg.position))
        x_d = pose_from_msg(msgs["setpoint"].pose)
        ospc, cfc = msgs["ospc"], msgs["cfc"]
        faults = self._faults(t_ns, ospc)
        hold = any(f.holds for f in faults)
        active = self.mode == "force_control"
        s_ospc = self.blends["ospc"].update(active and ospc.enabled)
        s_cfc = self.blends["cfc"].update(active and cfc.enabled)
        theta_d = self.command.update(x_d, [s_ospc * np.asarray(ospc.output)], s_cfc * np.asarray(cfc.output),
                                      hold=hold)             # weights 0: IK only (2.3.2)
        self.publisher.publish(JointState(header=self.header(t_ns), name=self.names, position=theta_d.tolist()))
        if faults:
            level = DiagnosticStatus.ERROR if hold else DiagnosticStatus.WARN
            self.report(level, "; ".join(f.message for f in faults[:3]),
                        {"holding": hold, "faults": len(faults)}, stamp_ns=t_ns)
        elif self.command.held:
            self.report(DiagnosticStatus.ERROR, "command outside the model (non-finite IK): holding", stamp_ns=t_ns)
        else:
            self.report(DiagnosticStatus.OK, f"ok ({self.mode})", stamp_ns=t_ns)

    def _faults(self, t_ns: int, ospc):
        f_msg, fk = self.latest.get("f"), self.latest.get("fk")
        now = t_ns * 1e-9
        times = {name: stamp_ns(msg) * 1e-9 for name, msg in self.latest.items()}
        x_d = np.asarray(ospc.reference) if len(ospc.reference) == 6 else None
        x = np.asarray(ospc.feedback) if len(ospc.feedback) == 6 else None
        c = self.robot.cable
        return self.monitor.check(
            now, f=None if f_msg is None else np.asarray(f_msg.f), f_min=c.f_min, f_max=c.f_max,
            x_d=x_d, x=x, fk_converged=True if fk is None else fk.converged, input_times=times)


def main(args=None):
    spin_node(JointCommandNode, args)


if __name__ == "__main__":
    main()

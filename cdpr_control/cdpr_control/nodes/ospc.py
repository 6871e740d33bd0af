"""Node ``ospc``: operational-space position control, one PI per DOF (3.16).

Subscribes ``setpoint`` (x_d) and ``platform/pose`` (x from the forward kinematics); publishes
``ospc/state`` (cdpr_msgs/ControllerState, ``output`` = x_OSPC [m, m, m, rad, rad, rad]).
Disabled, the output is zero (IK-only reference control). With ``force_controller`` naming the
hybrid force controller, it also subscribes ``<force_controller>/state`` and does not act along
the force direction while that controller makes, holds or releases contact (states A-D, R;
Raibert and Craig's selection, Fig. 5.2). While ``joint_command`` runs IK-only (its mode on
``joint_command/mode``, :mod:`.mode`) the output is not applied and the integrator is held.
Gains that make the loop unstable by the stability analysis (thesis 3.4,
:func:`cdpr_control.analysis.stability.ospc_instability`) are refused with the margins, unless
``allow_unstable`` is true.
"""
from __future__ import annotations


import numpy as np
from cdpr_msgs.msg import ControllerState, OperationalSetpoint
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped

from cdpr_control.control.hybrid_force_control import FORCE_CONTROLLED, parse_state, select_position_feedback
from cdpr_control.control.ospc import AXES, OperationalSpacePositionController, OSPCParams
from cdpr_control.control.params import default, section
from cdpr_control.control.safety import all_finite
from cdpr_control.control.preconditions import check_force_control, planned_home_forces

from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.conversions import from_vector3, pose_from_msg, setpoint_pose
from cdpr_control.ros.mode import follow_mode
from cdpr_control.ros.parameters import ParameterSet, ParamSpec, declare
from cdpr_control.ros.qos import CONTROL
from cdpr_control.ros.sync import StampSync

_D = OSPCParams()     # the defaults live in the dataclass (one source of truth)
PARAMS = [
    ParamSpec("enabled", default("ospc", "enabled"), "operational-space position control on; off = x_OSPC held at 0"),
    ParamSpec("K_p", _D.K_p.tolist(), "proportional gains K_p,OSPC per DOF x y z a b c [-] (3.16); table 3.1 gives z"),
    ParamSpec("T_i", _D.T_i.tolist(), "integrator reset times T_i,OSPC per DOF [s] (3.16); table 3.1 gives z"),
    ParamSpec("x_sat", _D.x_sat.tolist(), "output saturation per DOF [m, m, m, rad, rad, rad]"),
    ParamSpec("allow_unstable", False, "accept gains that the stability analysis (thesis 3.4) calls unstable"),
]
FORCE_CONTROLLER = ParamSpec("force_controller", "", "hybrid force controller whose force axis is not "
                             "position-controlled while it is in contact (Fig. 5.2); empty: none", read_only=True)


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md)."""
    return [*PARAMS, FORCE_CONTROLLER]


class OSPCNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("ospc", **kwargs)
        self.controller: OperationalSpacePositionController | None = None
        self.enabled = True
        self.precondition: str | None = None
        self.names = list(AXES)                     # shared by the published messages (never modified)
        force_controller = declare(self, FORCE_CONTROLLER)
        self._instabilities: dict = {}              # gain set -> the stability analysis' verdict
        self._live = False                          # (the start-up set is not analysed: see _validate)
        self.params = ParameterSet(self, parameters(self.robot), self._validate, self._apply)
        self._live = True
        self.publisher = self.create_publisher(ControllerState, "ospc/state", CONTROL)
        follow_mode(self, self._on_mode)
        inputs = {"setpoint": (OperationalSetpoint, "setpoint"), "pose": (PoseStamped, "platform/pose")}
        if force_controller:
            inputs["hpfc"] = (ControllerState, f"{force_controller}/state")
        self.sync = StampSync(self, inputs, primary="pose", callback=self._cycle, mode=self.sync_mode,
                              optional=("hpfc",) if force_controller else ())

    def _validate(self, v: dict) -> None:
        params = section(OSPCParams, v)
        params.validate()
        # live changes only: the analysis (python-control, 0.1-0.3 s) would delay the node's start
        # and the lockstep graph's first periods; the shipped sets are stable (tests/nodes/test_stability_refusal.py)
        if self._live and v["enabled"] and not v["allow_unstable"]:
            reason = self._instability(params)
            if reason:
                raise ValueError(f"{reason}; refused (set allow_unstable true to override)")

    def _instability(self, params: OSPCParams) -> str | None:
        """ospc_instability of these gains, remembered per gain set (the analysis takes ~0.3 s)."""
        from cdpr_control.analysis.stability import (ospc_instability)   # python-control: imported when first needed

        key = (tuple(params.K_p.tolist()), tuple(params.T_i.tolist()))
        if key not in self._instabilities:
            self._instabilities[key] = ospc_instability(self.robot, params, self.dt)
        return self._instabilities[key]

    def _apply(self, v: dict) -> None:
        params = section(OSPCParams, v)
        if self.controller is None:
            self.controller = OperationalSpacePositionController(params, self.dt)
        else:
            self.controller.set_params(params)
        if v["enabled"] != self.enabled:
            self.controller.reset()
        self.enabled = v["enabled"]
        # section 3.1.3: force control without OSPC needs a positive definite K_g; checked at home
        # for the minimal-tension distribution of the robot file (the node cannot see the others)
        self.precondition = None if self.enabled else check_force_control(
            self.robot, self.robot.home, planned_home_forces(self.robot), ospc_enabled=False)

    def _on_mode(self, ik_only: bool) -> None:
        self.controller.pi.hold = ik_only           # bumpless: no wind-up while not applied

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        x_d = setpoint_pose(msgs["setpoint"])
        reference = x_d.tolist()
        x = pose_from_msg(msgs["pose"].pose)
        hpfc = msgs.get("hpfc")
        if hpfc is not None and parse_state(hpfc.controller) in FORCE_CONTROLLED:
            # the force axis: F_d,0 (A-D), or the direction of the offset while releasing (R)
            axis = next((a for a in (from_vector3(msgs["setpoint"].force), np.asarray(hpfc.output[:3]))
                         if np.any(a != 0.0)), None)
            if axis is not None:
                x = select_position_feedback(x_d, x, axis / np.linalg.norm(axis))
        feedback = x.tolist()
        if not self.enabled and self.precondition:
            self.report(DiagnosticStatus.WARN, self.precondition, stamp_ns=t_ns)
        if self.enabled and all_finite(feedback) and all_finite(reference):
            pi = self.controller.pi
            output = {"output": self.controller.update(x_d, x), "integrator": pi.integrator,
                      "saturated": pi.saturated.tolist()}
        else:
            output = {"output": [0.0] * 6}
        # e = x_d - x element by element: the bits of numpy's subtraction
        self.publisher.publish(self.message_factory(ControllerState)(
            header=self.header(t_ns), controller="ospc", enabled=self.enabled, names=self.names,
            reference=reference, feedback=feedback, error=[a - b for a, b in zip(reference, feedback)], **output))


def main(args=None):
    spin_node(OSPCNode, args)


if __name__ == "__main__":
    main()

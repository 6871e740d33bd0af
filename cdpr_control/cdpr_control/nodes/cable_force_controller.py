"""Node ``cable_force_controller``: joint-space cable force control (3.19)-(3.23).

Subscribes ``force_distribution`` (f_d, limits), ``cable_forces`` (f at the platform) and
``winch/state`` (θ, for the free length l_t (2.14)); publishes ``cable_force_controller/state``
(cdpr_msgs/ControllerState, ``output`` = Δq_CFC [m] per cable). Disabled, it publishes Δq_CFC = 0:
the IK-only reference control of section 2.3.2. The computation, including the stiffness model
of (3.23) and the pre-tension Δq_0, is :class:`cdpr_control.control.cable_force_control.CableForceControl`;
Δq_0 comes from the home calibration (``home_forces``) or the mean of the first
``calibration_window`` samples (:mod:`cdpr_control.model.calibration`), as in the forward kinematics.

With ``force_controller`` naming the hybrid force controller (section 5.1.2), it also subscribes
``<force_controller>/state`` and ``setpoint`` (x_d, for the structure matrix A^T(x_d)) and runs
:class:`cdpr_control.control.hybrid_force_control.ContactCableForceControl` (as ControlLoop does): Δq_CFC is held while that controller
makes or loses contact (states A-C); in D and R the CFC runs, its feed-forward through the moving
average of ``T_MA`` except along the task axis, and the integral part along the task axis is
handed over to x_t: published per period on ``cable_force_controller/hand_over``
(cdpr_msgs/ControllerState, ``output`` = [F_a z_t; 0 0 0], the contact force F_a [N] taken out of the
integrator, ``enabled`` = Δq_CFC applied), which the hybrid force controller takes on x_t the next
period, as the in-process loop does.

While ``joint_command`` runs IK-only (its mode on ``joint_command/mode``, :mod:`.mode`) Δq_CFC is
not applied and the integrator is held (the filter and the calibration stay current).

Gains that make the loop unstable by the stability analysis (thesis 3.4,
:func:`cdpr_control.analysis.stability.cfc_instability`) are refused with the margins, unless
``allow_unstable`` is true.
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import CableForces, ControllerState, ForceDistribution, OperationalSetpoint
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState

from cdpr_control.control.cable_force_control import CableForceControl, CFCParams
from cdpr_control.control.hybrid_force_control import ContactCableForceControl, parse_state
from cdpr_control.control.params import default, section
from cdpr_control.control.safety import all_finite

from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.conversions import setpoint_pose
from cdpr_control.ros.mode import follow_mode
from cdpr_control.ros.parameters import ParameterSet, ParamSpec, calibration_params, declare, startup_calibration
from cdpr_control.ros.qos import CONTROL
from cdpr_control.ros.sync import StampSync

_D = CFCParams()      # the defaults live in the dataclass (one source of truth)
PARAMS = [
    ParamSpec("enabled", default("cable_force_controller", "enabled"), "cable force control on; off = IK-only reference control (2.3.2)"),
    ParamSpec("K_p", _D.K_p, "proportional gain K_p,CFC [-] (3.19), table 3.1", range=(0.0, 10.0)),
    ParamSpec("T_i", _D.T_i, "integrator reset time T_i,CFC [s] (3.19), table 3.1", range=(1e-3, 100.0)),
    ParamSpec("T_filter", _D.T_filter, "PT1 time constant of the force feedback T_1,r [s] (3.20), table 3.1", range=(0.0, 1.0)),
    ParamSpec("F_sat_n", _D.F_sat_n, "negative saturation of the PI part F_sat,n [N]", range=(0.0, 1e5)),
    ParamSpec("F_sat_p", _D.F_sat_p, "positive saturation of the PI part F_sat,p [N]", range=(0.0, 1e5)),
    ParamSpec("widen_band", _D.widen_band, "force distance to a limit where the saturation widens [N]", range=(1e-3, 1e5)),
    ParamSpec("widen_factor", _D.widen_factor, "saturation multiplier reached at a force limit [-]", range=(1.0, 100.0)),
    ParamSpec("stiffness_model", _D.stiffness_model, "K_l of (3.23): linear (k_spec nominal / l_t, as the thesis) or "
              "nonlinear (secant of (2.16)-(2.17))", choices=("linear", "nonlinear")),
    ParamSpec("internal_integral", _D.internal_integral, "the integral part of (3.19) integrates only internal forces "
              "(the nullspace of A^T(x_d), (2.41)): the pose is the OSPC's; needs force_controller (the set-point), "
              "and not in contact (5.1.2)"),
    ParamSpec("T_MA", default("hybrid_force_controller", "T_MA"), "moving average T_MA,HPFC of the set-point after a contact [s], "
              "table 5.1 (section 5.1.2)", range=(0.0, 60.0)),
    ParamSpec("allow_unstable", False, "accept gains that the stability analysis (thesis 3.4) calls unstable"),
]
HAND_OVER_NAMES = ["x", "y", "z", "a", "b", "c"]
FORCE_CONTROLLER = ParamSpec("force_controller", "", "hybrid force controller whose <name>/state pauses this "
                             "controller in contact (5.1.2); empty: none", read_only=True)


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md)."""
    return [*PARAMS, FORCE_CONTROLLER, *calibration_params(robot.m)]


class CableForceControllerNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("cable_force_controller", **kwargs)
        self.names = [f"cable_{i + 1}" for i in range(self.robot.m)]
        self.stage: CableForceControl | None = None
        self.contact: ContactCableForceControl | None = None   # the stage under hybrid force control
        self.dq_held = np.zeros(self.robot.m)
        self.force_controller = declare(self, FORCE_CONTROLLER)
        self._instabilities: dict = {}              # gain set -> the stability analysis' verdict
        self._live = False                          # (the start-up set is not analysed: see _validate)
        self.params = ParameterSet(self, parameters(self.robot), self._validate, self._apply)
        self._live = True
        self.stage.calibration = startup_calibration(self.robot, self.params.values)   # Δq_0 of (3.23)
        self.publisher = self.create_publisher(ControllerState, "cable_force_controller/state", CONTROL)
        follow_mode(self, self._on_mode)
        inputs = {
            "f_d": (ForceDistribution, "force_distribution"),
            "f": (CableForces, "cable_forces"),
            "theta": (JointState, "winch/state"),
        }
        if self.force_controller:
            inputs["hpfc"] = (ControllerState, f"{self.force_controller}/state")
            inputs["setpoint"] = (OperationalSetpoint, "setpoint")
            self.hand_over = self.create_publisher(ControllerState, "cable_force_controller/hand_over", CONTROL)
        self.sync = StampSync(self, inputs, primary="f", callback=self._cycle, mode=self.sync_mode,
                              optional=("hpfc", "setpoint") if self.force_controller else (),
                              urgent=("f",))     # the command path (intraprocess.py)

    def _validate(self, v: dict) -> None:
        params = section(CFCParams, v)
        params.validate()
        startup_calibration(self.robot, v)
        # live changes only: the analysis (python-control, 0.1-0.3 s) would delay the node's start
        # and the lockstep graph's first periods; the shipped sets are stable (tests/nodes/test_stability_refusal.py)
        if self._live and v["enabled"] and not v["allow_unstable"]:
            reason = self._instability(params)
            if reason:
                raise ValueError(f"{reason}; refused (set allow_unstable true to override)")

    def _instability(self, params: CFCParams) -> str | None:
        """cfc_instability of these gains, remembered per gain set (the analysis takes ~0.1 s)."""
        from cdpr_control.analysis.stability import (cfc_instability)   # python-control: imported when first needed

        key = (params.K_p, params.T_i, params.T_filter, params.stiffness_model)
        if key not in self._instabilities:
            self._instabilities[key] = cfc_instability(self.robot, params, self.dt)
        return self._instabilities[key]

    def _apply(self, v: dict) -> None:
        if self.stage is None:
            self.stage = CableForceControl(self.robot, self.dt, section(CFCParams, v), enabled=v["enabled"],
                                           start_ramp=True)
        else:
            self.stage.set_params(section(CFCParams, v), enabled=v["enabled"])
        if self.contact is None:
            self.contact = ContactCableForceControl(self.robot, self.stage, v["T_MA"], self.dt)
        else:
            self.contact.coupling.set_time_constant(v["T_MA"])

    def _on_mode(self, ik_only: bool) -> None:
        self.stage.controller.pi.hold = ik_only      # bumpless: no wind-up while not applied

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        fd_msg = msgs["f_d"]
        f_d_values, f_values, theta_values = fd_msg.f_d, msgs["f"].f, msgs["theta"].position
        stage = self.stage
        enabled = stage.enabled
        header = self.header(t_ns)          # (shared with the hand-over: messages are not modified)
        # the state message is built once, every field given (the constructor's own copies); the
        # reference, and the feedback unless filtered, straight from the messages' sequences, which
        # the constructor copies into the float64 arrays that f_d.tolist() and f.tolist() would fill
        if not _valid(self.robot.m, f_d_values, f_values, theta_values):
            self.report(DiagnosticStatus.ERROR, "invalid input (shape or non-finite); output 0", stamp_ns=t_ns)
            self.publisher.publish(self.message_factory(ControllerState)(
                header=header, controller="cable_force_controller", enabled=enabled, names=self.names,
                reference=f_d_values, feedback=f_values, output=[0.0] * self.robot.m))
            return
        f_d, f, theta = np.asarray(f_d_values), np.asarray(f_values), np.asarray(theta_values)
        f_ref, f_ff = f_d, None
        if self.force_controller:           # section 5.1.2: paused in A-C, running in D and R
            self.dq_held = self._contact(msgs, f_d, f, theta, fd_msg, t_ns, header)
            f_d, f_ff = self.contact.f_set, self.contact.f_ff
        else:
            self.dq_held = stage.update(f_d, f, theta, np.asarray(fd_msg.f_min), np.asarray(fd_msg.f_max))
        c = stage.controller
        f_fb = c.f_filtered
        if stage.enabled and f_fb is not None:
            saturated = c.pi.saturated.tolist()
            self.report(DiagnosticStatus.WARN if any(saturated) else DiagnosticStatus.OK,
                        "saturated" if any(saturated) else "ok", stamp_ns=t_ns)
            state = self.message_factory(ControllerState)(
                header=header, controller="cable_force_controller", enabled=enabled, names=self.names,
                reference=f_d_values, feedback=f_fb, error=f_ref - f_fb,
                integrator=c.pi.integrator, feedforward=f_d if f_ff is None else f_ff,
                output=self.dq_held, saturated=saturated)
        else:
            state = self.message_factory(ControllerState)(
                header=header, controller="cable_force_controller", enabled=enabled, names=self.names,
                reference=f_d_values, feedback=f_values, error=f_ref - f, output=self.dq_held)
        self.publisher.publish(state)

    def _contact(self, msgs: dict, f_d, f, theta, fd_msg, t_ns: int, header) -> np.ndarray:
        """The stage under hybrid force control (ContactCableForceControl) with the state of the
        hybrid force controller, its F_d,0 and x_d -> Δq_CFC; publishes the hand-over of the
        integral part."""
        hpfc, sp = msgs.get("hpfc"), msgs.get("setpoint")
        state = (parse_state(hpfc.controller) if hpfc is not None else None) or "I"
        F_d0 = x_d = F_vec = None
        if hpfc is not None and sp is not None:
            F_d0, F_vec = hpfc.reference[:3], hpfc.feedback[:3]
            # x_d only where the stage uses it (not idle with the ramp-out done: the most frequent
            # case by far); its pose StampSync found finite
            x_d = (setpoint_pose(sp) if self.contact.needs_setpoint(state) or self.stage.params.internal_integral
                   else None)
            if not (all_finite(F_d0) and (x_d is None or all_finite(x_d.tolist()))):
                F_d0 = x_d = F_vec = None
                self.report(DiagnosticStatus.ERROR, "invalid set-point or hybrid force controller state; "
                            "no hand-over this period", stamp_ns=t_ns)
        elif state != "I":
            self.report(DiagnosticStatus.WARN, "no set-point: no hand-over this period", stamp_ns=t_ns)
        contact = self.contact
        dq = contact.update(state, F_d0, x_d, f_d, f, theta, np.asarray(fd_msg.f_min), np.asarray(fd_msg.f_max),
                            F_vec)
        F_a, z = contact.F_a, contact.z_t
        stage = self.stage
        self.hand_over.publish(self.message_factory(ControllerState)(
            header=header, controller="cable_force_controller:hand_over",
            enabled=bool(stage.enabled and not stage.controller.pi.hold), names=HAND_OVER_NAMES,
            output=(F_a * z[0], F_a * z[1], F_a * z[2], 0.0, 0.0, 0.0)))
        return dq


def _valid(m: int, *inputs) -> bool:
    return all(len(v) == m and all_finite(v) for v in inputs)


def main(args=None):
    spin_node(CableForceControllerNode, args)


if __name__ == "__main__":
    main()

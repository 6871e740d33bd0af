"""Node ``force_distribution``: wrench set-point (3.26) and cable force set-point f_d (3.27)-(3.28).

Subscribes ``setpoint`` (x_d, ẋ_d, ẍ_d) and ``platform/wrench`` (the measured w = -A^T f of the
forward kinematics node); publishes ``force_distribution`` (cdpr_msgs/ForceDistribution: f_d,
f_ref, limits used, w_d, status and solver diagnostics). Service
``force_distribution/set_tension_level`` (cdpr_msgs/SetTensionLevel).

w_d = w + (I - G_w) w_dyn (3.26) with the measured disturbance saturated (section 3.6.1), or
w_d = w_dyn with ``wrench_source = model`` (3.1). The tension level 0..1 sets
f_ref = f_min + level (f_max - f_min) (3.27), ramped at ``tension_rate``: 0 is the minimal
tension (QP), 0.5 the medium one (= ACF). The computation is
:class:`cdpr_control.control.force_setpoint.ForceSetpoint`.

With ``payload_input`` (read-only) it also subscribes ``load_compensation/payload``
(geometry_msgs/InertiaStamped) and adds the identified payload's wrench (a point mass at its cog,
:func:`cdpr_control.control.load_compensation.payload_wrench`) to the model wrench w_dyn, so that a heavy
payload is not clipped by the disturbance saturation and enters f_d also with ``wrench_source: model``.

With ``force_controller`` (read-only) naming the hybrid force controller it also subscribes
``<force_controller>/state`` and, while that controller acts (states A-D, R), replaces the
measured contact force along the task axis by the desired one in the wrench it distributes
(section 5.1.2, :func:`cdpr_control.control.hybrid_force_control.expected_contact_wrench`), so the cables
are planned for the contact being made and nothing of the contact stays in the wrench filter
after the release.

With ``guiding_controller`` (read-only) naming the admittance controller it also subscribes
``<guiding_controller>/state`` and, while that controller is the set-point source (``enabled``),
hands its user wrench w_Adm (5.9) (``feedback``) to the force set-point's hand's reserve
(:meth:`cdpr_control.control.force_setpoint.ForceSetpoint.set_user_wrench`, docs/admittance.md).
The state of t_k goes with the set-point x_d,Adm it computed, that of t_k+1: it acts in period
k + 1, as ``ControlLoop.step``'s ``w_user`` with :class:`cdpr_sim.closed_loop.HandGuiding`.
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import ControllerState, ForceDistribution, OperationalSetpoint
from cdpr_msgs.srv import SetTensionLevel
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import InertiaStamped, WrenchStamped
from rclpy.parameter import Parameter

from cdpr_control.force_distribution import BACKENDS, METHODS, Status
from cdpr_control.control.force_setpoint import ForceSetpoint, ForceSetpointParams
from cdpr_control.control.hybrid_force_control import parse_state
from cdpr_control.control.params import section

from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.conversions import setpoint_from_msg, wrench_from_msg, wrench_to_msg
from cdpr_control.ros.parameters import ParameterSet, ParamSpec
from cdpr_control.ros.qos import CONTROL
from cdpr_control.ros.sync import StampSync


PAYLOAD_INPUT = ParamSpec("payload_input", False, "add the payload identified by load_compensation "
                          "(load_compensation/payload) to the model wrench w_dyn", read_only=True)
FORCE_CONTROLLER = ParamSpec("force_controller", "", "hybrid force controller whose desired contact force "
                             "replaces the measured one in the distributed wrench (5.1.2); empty: none",
                             read_only=True)
GUIDING_CONTROLLER = ParamSpec("guiding_controller", "", "admittance controller whose user wrench w_Adm "
                               "(5.9) keeps the hand's reserve on the cable forces while it guides; empty: none",
                               read_only=True)
_OK, _WARN, _ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
_INFEASIBLE, _OVERLOADED = Status.INFEASIBLE, Status.OVERLOADED


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md); the stage's of
    ForceSetpointParams' field names (section), the force limits the robot file's."""
    c, d = robot.cable, ForceSetpointParams()       # the defaults live in the dataclass (one source of truth)
    return [
        ParamSpec("method", d.method, "cable force algorithm: " + ", ".join(sorted(METHODS)), choices=tuple(sorted(METHODS))),
        ParamSpec("backend", d.backend, "QP solver: " + ", ".join(BACKENDS), choices=tuple(BACKENDS)),
        ParamSpec("tension_level", d.tension_level, "f_ref = f_min + level (f_max - f_min) (3.27) [0..1]", range=(0.0, 1.0)),
        ParamSpec("tension_rate", d.tension_rate, "ramp of the tension level [1/s]; 0 = step", range=(0.0, 1e3)),
        ParamSpec("f_min", c.f_min.tolist(), "minimum cable force per cable [N] (2.39)"),
        ParamSpec("f_max", c.f_max.tolist(), "maximum cable force per cable [N] (2.39)"),
        ParamSpec("overload_factor", d.overload_factor, "f_max may rise to this multiple at the workspace border (3.6.2) [-]", range=(1.0, 5.0)),
        ParamSpec("overload_rate", d.overload_rate, "max rate of the overload raise [1/s]; 0 = instant", range=(0.0, 1e3)),
        ParamSpec("wrench_source", d.wrench_source, "measured: w_d = w + (I - G_w) w_dyn (3.26); model: w_d = w_dyn (3.1)",
                  choices=("measured", "model")),
        ParamSpec("T_d_w", d.T_d_w, "transfer delay T_d,w of the Smith predictor (3.25) [s]", range=(0.0, 0.5)),
        ParamSpec("wrench_deviation_max", d.wrench_deviation_max, "saturation of the measured disturbance wrench (3.24) relative "
                  "to the platform weight m g (torques: times the mean platform radius) [-] (section 3.6.1)",
                  range=(0.0, 100.0)),
        ParamSpec("T_wrench_filter", d.T_wrench_filter, "PT1 time constant on the disturbance w - w_dyn(t - T_d,w) of (3.24) [s]", range=(0.0, 1.0)),
        PAYLOAD_INPUT, FORCE_CONTROLLER, GUIDING_CONTROLLER,
    ]


class ForceDistributionNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("force_distribution", **kwargs)
        self.stage: ForceSetpoint | None = None
        self.params = ParameterSet(self, parameters(self.robot), self._validate, self._apply)
        self.payload_input = bool(self.params.values[PAYLOAD_INPUT.name])
        self.publisher = self.create_publisher(ForceDistribution, "force_distribution", CONTROL)
        self.create_service(SetTensionLevel, "force_distribution/set_tension_level", self._on_set_tension_level)
        force_controller = self.params.values[FORCE_CONTROLLER.name]
        guiding_controller = self.params.values[GUIDING_CONTROLLER.name]
        self._w_user = None     # the user's wrench of the last period's admittance state (_user_wrench)
        inputs = {"setpoint": (OperationalSetpoint, "setpoint"), "wrench": (WrenchStamped, "platform/wrench")}
        if self.payload_input:
            inputs["payload"] = (InertiaStamped, "load_compensation/payload")
        if force_controller:
            inputs["hpfc"] = (ControllerState, f"{force_controller}/state")
        if guiding_controller:
            inputs["guide"] = (ControllerState, f"{guiding_controller}/state")
        self.sync = StampSync(self, inputs, primary="wrench", callback=self._cycle, mode=self.sync_mode,
                              optional=tuple(n for n in ("payload", "hpfc", "guide") if n in inputs))

    def _validate(self, v: dict) -> None:
        p = section(ForceSetpointParams, v)
        p.validate(self.robot.m)
        if np.any(p.f_min < 0) or np.any(p.f_min >= p.f_max):
            raise ValueError("force limits need 0 <= f_min < f_max for every cable")

    def _apply(self, v: dict) -> None:
        if self.stage is None:
            self.stage = ForceSetpoint(self.robot, self.dt, section(ForceSetpointParams, v))
        else:
            self.stage.set_params(section(ForceSetpointParams, v))

    def _on_set_tension_level(self, request, response):
        if len(request.f_ref):
            try:
                self.stage.set_reference(request.f_ref)
                response.success, response.message = True, "f_ref set"
            except ValueError as exc:
                response.success, response.message = False, str(exc)
        else:
            result = self.set_parameters([Parameter("tension_level", value=float(request.level))])[0]
            response.success, response.message = result.successful, result.reason or "tension level set"
        response.f_ref = self.stage.distributor.f_ref.tolist()
        return response

    @staticmethod
    def _contact(hpfc) -> tuple:
        """(state letter, F_d,0, F_vec) of the hybrid force controller's state message."""
        return (parse_state(hpfc.controller), np.asarray(hpfc.reference[:3], dtype=float),
                np.asarray(hpfc.feedback[:3], dtype=float))

    def _user_wrench(self, guide) -> np.ndarray | None:
        """w_Adm of the admittance controller's state while it guides, else None (a feedback that is
        no wrench is reported and ignored)."""
        if guide is None or not guide.enabled:
            return None
        if len(guide.feedback) != 6 or not np.all(np.isfinite(guide.feedback)):
            self.input_fault(self.sync.topics["guide"], "feedback (w_Adm) is not 6 finite values")
            return None
        return np.asarray(guide.feedback, dtype=float)

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        x_d, xdot_d, xddot_d = setpoint_from_msg(msgs["setpoint"])
        payload = msgs.get("payload")
        w_model = None
        if payload is not None:
            p = payload._inertia                  # (the slots: every period)
            com = p._com
            w_model = self.stage.payload_wrench(x_d, xdot_d, xddot_d, p._m, (com._x, com._y, com._z))
        hpfc = msgs.get("hpfc")
        contact = None if hpfc is None else self._contact(hpfc)
        # the user's wrench of t_k-1: the one the set-point of t_k was computed with (the hand's reserve)
        self.stage.set_user_wrench(self._w_user)
        self._w_user = self._user_wrench(msgs.get("guide"))
        res = self.stage.update(x_d, xdot_d, xddot_d, wrench_from_msg(msgs["wrench"].wrench), w_model, contact)
        max_violation = float(res.max_violation)
        self.publisher.publish(self._message(res, max_violation, t_ns))
        status = res.status
        if status == _INFEASIBLE:
            self.report(_ERROR, f"no feasible distribution: max violation {max_violation:.1f} N", stamp_ns=t_ns)
        elif status == _OVERLOADED:
            self.report(_WARN, "feasible only with raised f_max (workspace border)", stamp_ns=t_ns)
        else:
            self.report(_OK, "feasible", stamp_ns=t_ns)

    def _message(self, res, max_violation: float, t_ns: int) -> ForceDistribution:
        return self.message_factory(ForceDistribution)(
            header=self.header(t_ns), f_d=res.f, f_ref=res.f_ref, f_min=res.f_min,
            f_max=res.f_max, w_d=wrench_to_msg(self.stage.w_d), method=res.method, status=int(res.status),
            max_violation=max_violation, residual=float(res.residual), iterations=int(res.iterations),
            solve_time=float(res.solve_time))


def main(args=None):
    spin_node(ForceDistributionNode, args)


if __name__ == "__main__":
    main()

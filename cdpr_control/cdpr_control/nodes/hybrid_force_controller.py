"""Node ``hybrid_force_controller``: hybrid position and force control, thesis section 5.1 (Fig. 5.3).

Subscribes ``setpoint`` (cdpr_msgs/OperationalSetpoint; ``force`` = F_d,0, the force axes U V W),
``platform/wrench`` (geometry_msgs/WrenchStamped, the measured wrench w (2.11)) and
``platform/pose`` (the pose estimate, which paces the node with the forward kinematics); publishes
``hybrid_force_controller/state`` (cdpr_msgs/ControllerState) every period, enabled or not, and
``/diagnostics`` when the level or the reason changes (state, saturation, F_d limited, contact
refused), a reason's changing numbers at most once a second
(:class:`cdpr_control.control.hybrid_force_control.ContactDiagnostics`). The joint command adds the state's ``output``
(x_d,HPFC) to x_d when ``hybrid_force_controller`` is one of its ``offset_inputs``.

ControllerState fields (names x y z a b c, base frame):

- ``controller``: ``hybrid_force_controller:<state>``, the state of Fig. 5.4: I idle, A approach,
  B brake, C contact lost, D force control, R release;
- ``enabled``: the output is in use (``enabled``, or releasing after a disable);
- ``reference``: F_d,0 [N] and 0 0 0; ``feedback``: the contact force vector F [N] and 0 0 0;
  ``error``: their difference (e_F = F_d - F is its component along the task z axis);
- ``output``: x_d,HPFC + x_comp = [R_t [0 0 x_t] + x_comp; 0 0 0] [m, rad], x_comp = -F_ff / k_t z_t
  the hand-over offset of section 5.1.2 (:class:`cdpr_control.control.hybrid_force_control.ContactHandOver`:
  the contact force F_ff the cable force controller's feed-forward presses with in D and R, over
  the contact stiffness k_t measured in B); ``integrator``: the task z axis times the integral
  part of x_t; ``feedforward``: the position-controlled part of x_t (A, B, C, R);
- ``saturated``: |x_t| at ``x_max`` (all six entries alike).

It also subscribes ``cable_force_controller/hand_over`` (cdpr_msgs/ControllerState, see the node
``cable_force_controller``): the contact force F_a the cable force controller's integral part
handed over in a period is taken on x_t (F_a / k_t, :meth:`HybridForceControl.absorb`) at the
start of the next period, as the in-process loop does; its ``enabled`` (Δq_CFC applied) switches
x_comp. Without that topic x_comp is 0 and nothing is handed over.

It subscribes ``force_distribution`` (not synchronised: the last one) for the distribution's f_min
and f_max: while enabled or active, F_d is limited to the contact capacity of the pose x_d over 1.2
(:meth:`cdpr_control.control.hybrid_force_control.HybridForceControl.update`), the state's
``reference`` is then the limited F_d,0, and ``/diagnostics`` carries a WARN naming the F_d asked
for, the capacity and the pose. Where what the capacity leaves is below the smallest force the
controller regulates (``HybridForceControl.minimum_contact_force``) contact is refused: an ERROR
naming them, and ``enabled: true`` (a program's M103) is refused there with that reason, so the
program fails at its M103.

The computation is :class:`cdpr_control.control.hybrid_force_control.HybridForceStage` (as ControlLoop runs it).
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import ControllerState, ForceDistribution, OperationalSetpoint
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped, WrenchStamped

from cdpr_control.control.force_setpoint import ForceSetpointParams
from cdpr_control.control.hybrid_force_control import (CONTACT, ERROR, IDLE, OK, WARN, ContactDiagnostics,
    HPFCParams, HybridForceStage, format_state, refusal_message)
from cdpr_control.control.ospc import AXES

from cdpr_control.control.params import default, section
from cdpr_control.control.safety import all_finite
from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.conversions import from_vector3, setpoint_pose, wrench_from_msg
from cdpr_control.ros.parameters import ParameterSet, ParamSpec
from cdpr_control.ros.qos import CONTROL
from cdpr_control.ros.sync import StampSync, stamp_ns

NAME = "hybrid_force_controller"
_LEVELS = {OK: DiagnosticStatus.OK, WARN: DiagnosticStatus.WARN, ERROR: DiagnosticStatus.ERROR}
_ZERO3, _ZEROS = [0.0] * 3, [0.0] * 6     # (the message constructor copies them)
_D = HPFCParams()          # the one source of the defaults (table 5.1)
PARAMS = [
    ParamSpec("enabled", default("hybrid_force_controller", "enabled"), "hybrid position/force control on (M103) or off (M104; releases the contact)"),
    ParamSpec("K_p", _D.K_p, "proportional gain K_p,HPFC (effective stiffness) [N/m], output e_F / K_p (5.3), "
              "table 5.1", range=(1.0, 1e9)),
    ParamSpec("T_i", _D.T_i, "integrator reset time T_i,HPFC [s] (5.3), table 5.1", range=(1e-3, 1e4)),
    ParamSpec("T_d", _D.T_d, "derivative time constant T_d,HPFC [s] (5.3), table 5.1", range=(0.0, 10.0)),
    ParamSpec("F_th", _D.F_th, "threshold force F_th of contact detection [N], table 5.1", range=(1e-3, 1e5)),
    ParamSpec("v_max", _D.v_max, "maximal approach velocity v_max,HPFC [m/s], table 5.1", range=(1e-5, 1.0)),
    ParamSpec("a_max", _D.a_max, "acceleration of x_t when approaching, braking, releasing [m/s^2]",
              range=(1e-4, 100.0)),
    ParamSpec("x_max", _D.x_max, "saturation of x_t, farthest approach [m]", range=(1e-5, 1.0)),
    ParamSpec("T_F", _D.T_F, "PT1 time constant on the contact force [s]", range=(0.0, 1.0)),
    ParamSpec("payload", _D.payload, "known payload whose weight is no contact force [kg]", range=(0.0, 1e4)),
    ParamSpec("k_env", _D.k_env, "stiffest surface expected [N/m]: the approach is slowed to F_d / (sqrt(k_env m) "
              "+ d_env) where that is below v_max (k_env = d_env = 0: v_max always)", range=(0.0, 1e12)),
    ParamSpec("d_env", _D.d_env, "damping of the stiffest surface expected [N s/m] (see k_env)", range=(0.0, 1e9)),
    ParamSpec("T_on", _D.T_on, "the joint command's switch-on ramp of this output [s] (joint_command's "
              "transfer_time): x_t leaves 0 in A no earlier than T_on after the output is reported active",
              range=(0.0, 10.0)),
    ParamSpec("tare", _D.tare, "zero the contact force when an approach starts in free space (sensor offsets)"),
    ParamSpec("T_wrench_filter", ForceSetpointParams().T_wrench_filter, "PT1 of the contact force handed over "
              "to the cable force controller's feed-forward [s]: force_distribution's T_wrench_filter, whose "
              "filter carries it into f_d (5.1.2)", range=(0.0, 1.0)),
]


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md)."""
    return list(PARAMS)


class HybridForceControllerNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__(NAME, **kwargs)
        self.stage: HybridForceStage | None = None
        self.cfc_on = False                # the last cable_force_controller/hand_over: Δq_CFC applied
        self.hand_overs: list = []         # hand-overs not yet taken on x_t
        self.limits = None                 # the force distribution's last (f_min, f_max) [N]
        self.last_setpoint = None          # the last period's set-point message: M103's refusal (_validate)
        self.diagnostics = ContactDiagnostics()
        self.params = ParameterSet(self, parameters(self.robot), self._validate, self._apply)
        self.publisher = self.create_publisher(ControllerState, f"{NAME}/state", CONTROL)
        self.sync = StampSync(self, {
            "setpoint": (OperationalSetpoint, "setpoint"),
            "wrench": (WrenchStamped, "platform/wrench"),
            "pose": (PoseStamped, "platform/pose"),
        }, primary="pose", callback=self._cycle, mode=self.sync_mode)
        # the previous period's hand-over (not synchronised: the CFC of period k runs after this node)
        self.create_subscription(ControllerState, "cable_force_controller/hand_over", self._on_hand_over, CONTROL,
                                 adapted=True)
        # the distribution's limits for the pose's contact capacity (not synchronised either: the
        # distribution of period k runs after this node; ControlLoop takes those of period k - 1 too)
        self.create_subscription(ForceDistribution, "force_distribution", self._on_distribution, CONTROL,
                                 adapted=True)

    def _on_distribution(self, msg) -> None:
        # kept as received (a payload's read-only arrays, a message's sequences): the stage converts
        # them only where the pose's capacity matters (HybridForceControl._limited), not every period
        f_min, f_max = msg.f_min, msg.f_max
        m = self.robot.m
        if len(f_min) == m and len(f_max) == m and all_finite(f_min) and all_finite(f_max):
            self.limits = (f_min, f_max)

    def _on_hand_over(self, msg) -> None:
        self.cfc_on = bool(msg.enabled)
        if msg.enabled and len(msg.output) == 6 and len(self.hand_overs) < 100:
            self.hand_overs.append(msg)

    def _validate(self, v: dict) -> None:
        params = section(HPFCParams, v)
        params.validate()
        if v["enabled"] and self.stage is not None and not self.stage.control.enabled:
            # M103 where the pose's capacity leaves less than the controller regulates: refused, and
            # the program that asked fails at its M103 with the reason (the interpreter reports a
            # refused parameter); a refusal later in contact releases and reports ERROR (_cycle)
            reason = self._refusal(params)
            if reason is not None:
                raise ValueError(reason)

    def _refusal(self, params: HPFCParams) -> str | None:
        """Why contact would be refused at the last set-point (None: it would not, or not known)."""
        if self.last_setpoint is None or self.limits is None or self.robot is None:
            return None
        F_d0, x_d = from_vector3(self.last_setpoint.force), setpoint_pose(self.last_setpoint)
        probe = HybridForceStage(self.robot, self.dt, params, enabled=True).control
        s = probe.update(F_d0, np.zeros(6), x_d, self.limits)
        return refusal_message(s, x_d, probe.minimum_contact_force()) if s.refused else None

    def _apply(self, v: dict) -> None:
        if self.stage is None:
            self.stage = HybridForceStage(self.robot, self.dt, section(HPFCParams, v), v["T_wrench_filter"],
                                          enabled=v["enabled"])
        else:
            self.stage.control.set_params(section(HPFCParams, v))
            self.stage.control.enabled = v["enabled"]
            self.stage.hand_over.set_time_constant(v["T_wrench_filter"])

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        stage = self.stage
        z_t = stage.control.z_t
        later = []
        for msg in self.hand_overs:        # in lockstep the one of period k - 1; each taken once
            if stamp_ns(msg) < t_ns:
                if stage.takes_over:       # (F_a only where it is taken: not in most periods)
                    stage.take_over(float(z_t @ np.asarray(msg.output[:3], dtype=float)))
            else:
                later.append(msg)
        self.hand_overs = later
        setpoint = msgs["setpoint"]
        c = stage.control           # x_d only where the capacity may limit F_d (not idle and disabled)
        x_d = setpoint_pose(setpoint) if c.enabled or c.state != IDLE else None
        s, output = stage.update(from_vector3(setpoint.force), wrench_from_msg(msgs["wrench"].wrench),
                                 self.cfc_on, x_d, self.limits)
        # the fields' arithmetic in floats: element by element what numpy's would give, without
        # its call overhead on six numbers
        x = s.x.tolist()
        feedforward = _ZEROS if s.state in (CONTACT, IDLE) else x     # the position-controlled x_t
        reference, feedback = s.F_d0.tolist() + _ZERO3, s.F_vec.tolist() + _ZERO3
        integrator = s.integrator
        self.publisher.publish(self.message_factory(ControllerState)(
            header=self.header(t_ns), controller=format_state(NAME, s.state), enabled=s.active, names=list(AXES),
            reference=reference, feedback=feedback, error=[r - f for r, f in zip(reference, feedback)],
            integrator=[integrator * z for z in s.z_t.tolist()] + _ZERO3, feedforward=feedforward,
            output=output.tolist(), saturated=[bool(s.saturated)] * 6))
        self.last_setpoint = setpoint      # (M103's refusal reads it: _validate)
        # published when the level or the reason change (state, saturation, F_d limited, contact
        # refused), the changing numbers of a reason at most every DIAGNOSTICS_REPEAT s
        # (ContactDiagnostics; each period until session 13)
        report = self.diagnostics.update(s, x_d, t_ns * 1e-9, c.minimum_contact_force())
        if report is not None:
            level, message, values = report
            self.report(_LEVELS[level], message, values, stamp_ns=t_ns, always=True)


def main(args=None):
    spin_node(HybridForceControllerNode, args)


if __name__ == "__main__":
    main()

"""Node ``admittance_controller``: hand guiding with virtual workspace zones, thesis section 5.2.

Subscribes ``setpoint`` (the set-point in force) and ``platform/wrench`` (the measured wrench w of
(2.11)), synchronised per period. Publishes every period, stamped with that period t_k:

- ``admittance_controller/setpoint`` (cdpr_msgs/OperationalSetpoint): x_d,Adm for the *next*
  period t_k+1 (the wrench of a period can only act on the next one); while hand guiding is off it
  repeats the set-point in force.
- ``admittance_controller/state`` (cdpr_msgs/ControllerState): ``enabled`` = this node is the
  set-point source (hand guiding on, or braking to rest after it was switched off); ``reference``
  = the zone origin x_0, ``feedback`` = w_Adm (5.9) [N, N m], ``error`` = x_d,Adm - x_0,
  ``output`` = x_d,Adm, ``feedforward`` = its Kardan rates, ``saturated`` = a velocity,
  acceleration or hard-box limit acted, per axis x y z a b c.

The ``gcode_interpreter`` with ``setpoint_source: admittance_controller`` forwards this set-point
on ``setpoint`` while ``enabled`` and keeps the last one when it ends (docs/admittance.md), so the
switch between program mode and hand guiding has no jump. Switch with the parameter
``hand_guiding`` or the service ``~/hand_guiding`` (std_srvs/SetBool); switching on is refused
while a program runs. The zone the platform is in is reported on ``/diagnostics``. Zones whose hard
box would leave the wrench-feasible workspace are shrunk to fit (``fitted_settings``), logged and
reported (WARN) while guiding; refused only where not even the wall's reach fits.
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import ControllerState, OperationalSetpoint, ProgramStatus
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from rclpy.parameter import Parameter
from std_srvs.srv import SetBool

from cdpr_control.control.admittance import AdmittanceController, default_parameters, fitted_settings
from cdpr_control.control.ospc import AXES
from cdpr_control.ros.message_builders import builder

from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.conversions import (accel_to_msg, bare, pose_to_msg, setpoint_from_msg, setpoint_pose,
    twist_to_msg, wrench_from_msg)
from cdpr_control.ros.parameters import ParameterSet, ParamSpec
from cdpr_control.ros.qos import CONTROL, STATUS
from cdpr_control.ros.sync import StampSync

_D = default_parameters()
_DESCRIPTIONS = {
    "v_max": ("velocity limit of x_d,Adm per axis [m/s, rad/s]", (1e-6, 10.0)),
    "a_max": ("acceleration limit of x_d,Adm per axis [m/s^2, rad/s^2]", (1e-6, 1e3)),
    "T_filter": ("PT1 time constant of the user wrench (5.9) [s]", (0.0, 1.0)),
    "dead_band": ("dead band of the user wrench per axis [N, N m]", (0.0, 1e3)),
    "w_max": ("saturation of the user wrench per axis [N, N m]", (1e-6, 1e4)),
    "tare_on_enable": ("at switch-on take the remaining wrench as zero (the thesis' w_init)", None),
    "tare_time": ("the tare is the mean remaining wrench over this time after switch-on [s]", (0.0, 10.0)),
    "inertia_compensation": ("remove the platform's inertia wrench of the set-point (m_p xddot_d of (5.9))", None),
    "payload_mass": ("known payload on the platform [kg], removed from the measured wrench", (0.0, 1e4)),
    "payload_center_of_gravity": ("its centre of gravity in the platform frame [m]", None),
    "zones.origin": ("zone origin x_0 relative to the robot's home [m, m, m, rad, rad, rad]", None),
    "zones.rest.radius": ("radius R_1 of the rest sphere, zone 1 [m]", (1e-6, 10.0)),
    "zones.rest.c": ("zone 1 stiffness towards x_0 per axis [N/m, N m/rad]", None),
    "zones.rest.d": ("zone 1 damping per axis [N s/m, N m s/rad]", None),
    "zones.rest.m": ("zone 1 virtual mass per axis [kg, kg m^2]", None),
    "zones.free.box": ("half-widths of the virtual workspace, zone 2, about x_0 [m, m, m, rad, rad, rad]", None),
    "zones.free.c": ("zone 2 stiffness towards x_0 per axis (0: free) [N/m, N m/rad]", None),
    "zones.free.d": ("zone 2 damping per axis [N s/m, N m s/rad]", None),
    "zones.free.m": ("zone 2 virtual mass per axis [kg, kg m^2]", None),
    "zones.wall.c": ("zone 3 wall stiffness normal to the box faces per axis [N/m, N m/rad]", None),
    "zones.wall.d": ("zone 3 damping per axis [N s/m, N m s/rad]", None),
    "zones.wall.m": ("zone 3 virtual mass per axis [kg, kg m^2]", None),
    "zones.force_margin": ("the zones are fitted to the wrench-feasible workspace of the cable limits narrowed by "
                           "this on both sides: the force control's tracking and the force sensors' error [N]",
                           (0.0, 1e4)),
}
PARAMS = [ParamSpec("hand_guiding", False, "hand guiding on: this node is the set-point source")] + [
    ParamSpec(name, _D[name], *_DESCRIPTIONS[name][:1], range=_DESCRIPTIONS[name][1]) for name in _D]


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md)."""
    return list(PARAMS)
_BUSY = (ProgramStatus.RUNNING, ProgramStatus.STOPPING, ProgramStatus.PAUSED)
_ZEROS = [0.0] * 6
_ZERO_TWIST, _ZERO_ACCEL = twist_to_msg(_ZEROS), accel_to_msg(_ZEROS)  # shared: messages are never modified
MAX_CATCH_UP = 50      # periods one free-running cycle may integrate (a longer gap is a stall, not a skip)


class AdmittanceControllerNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("admittance_controller", **kwargs)
        self.controller: AdmittanceController | None = None
        self._last_ns: int | None = None
        self._origin_of, self._origin_floats = None, []     # (see _origin)
        self.clipping_note = ""          # how the zones were shrunk to fit the WFW (fitted_settings), reported while guiding
        self.program_state = ProgramStatus.IDLE
        self.create_subscription(ProgramStatus, "program_status", self._on_status, STATUS)
        self.params = ParameterSet(self, parameters(self.robot), self._validate, self._apply)
        self.setpoint_pub = self.create_publisher(OperationalSetpoint, "admittance_controller/setpoint", CONTROL)
        self.state_pub = self.create_publisher(ControllerState, "admittance_controller/state", CONTROL)
        self.create_service(SetBool, "~/hand_guiding", self._on_switch)
        self.sync = StampSync(self, {"setpoint": (OperationalSetpoint, "setpoint"),
                                     "wrench": (WrenchStamped, "platform/wrench")},
                              primary="wrench", callback=self._cycle, mode=self.sync_mode)

    def _on_status(self, msg: ProgramStatus) -> None:
        self.program_state = msg.state

    def _validate(self, v: dict) -> None:
        fitted_settings({k: v[k] for k in _D}, self.robot)
        switching_on = v["hand_guiding"] and (self.controller is None or not self.controller.enabled)
        if switching_on and self.program_state in _BUSY:
            raise ValueError("a program is running: hand guiding can start when it has ended")

    def _apply(self, v: dict) -> None:
        params, zones, robot, clipping = fitted_settings({k: v[k] for k in _D}, self.robot)
        self.clipping_note = "" if clipping is None else "; " + clipping.text()
        if clipping is not None:
            self.get_logger().warning(clipping.text())
        if self.controller is None:
            self.controller = AdmittanceController(robot, self.dt, params, zones)
        else:
            self.controller.configure(params, zones, robot)
        if v["hand_guiding"]:
            self.controller.enable()
        else:
            self.controller.disable()

    def _on_switch(self, request, response):
        result = self.set_parameters([Parameter("hand_guiding", value=bool(request.data))])[0]
        response.success, response.message = result.successful, result.reason or (
            "hand guiding on" if request.data else "hand guiding off (braking to rest)")
        return response

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        sp = msgs["setpoint"]
        if not self.controller.active:
            self._idle(sp, t_ns)
            return
        w = wrench_from_msg(msgs["wrench"].wrench)
        x_d, xdot_d, xddot_d = setpoint_from_msg(sp)
        if not all(np.all(np.isfinite(v)) for v in (w, x_d, xdot_d, xddot_d)):
            # never guide on garbage: brake to rest from the last good state, ignoring the input
            if self.params.values["hand_guiding"]:
                self.set_parameters([Parameter("hand_guiding", value=False)])
            self.report(DiagnosticStatus.ERROR, "non-finite wrench or set-point: hand guiding off", stamp_ns=t_ns)
            s = self.controller.system
            w, x_d, xdot_d, xddot_d = np.zeros(6), s.x.copy(), None, None
        # lockstep: one period per call; free-running, the periods since the last call (the wrench
        # of skipped periods held), so the virtual system keeps the simulated or real time
        periods = 1 if self._last_ns is None else int(np.clip(round((t_ns - self._last_ns) * 1e-9 / self.dt),
                                                               1, MAX_CATCH_UP))
        self._last_ns = t_ns
        out = self.controller.step(w, x_d, xdot_d, xddot_d, periods)
        xdot, xddot = out.twist()
        header = self.header(t_ns, sp.header.frame_id or "base")
        self.setpoint_pub.publish(builder(OperationalSetpoint)(
            header=header, pose=pose_to_msg(out.x), velocity=twist_to_msg(xdot), acceleration=accel_to_msg(xddot),
            force=sp.force, line=0))
        x_0 = self.controller.zones.x_0
        self.state_pub.publish(self.message_factory(ControllerState)(
            header=header, controller="admittance_controller", enabled=out.active, names=list(AXES),
            reference=x_0.tolist(), feedback=out.w_user.tolist(), error=(out.x - x_0).tolist(),
            feedforward=out.xd.tolist(), output=out.x.tolist(), saturated=out.limited.tolist()))
        if out.active:
            zone = self.controller.zones.zones[out.zone].name
            state = "braking" if self.controller.braking else f"zone {zone}"
            level = DiagnosticStatus.WARN if out.limited.any() or self.clipping_note else DiagnosticStatus.OK
            self.report(level, f"hand guiding, {state}" + (" (limited)" if out.limited.any() else "") + self.clipping_note,
                        stamp_ns=t_ns)

    def _idle(self, sp: OperationalSetpoint, t_ns: int) -> None:
        """Not guiding: the set-point passes through at rest (what the controller returns then), without
        the controller's work (this node runs every period of every graph, mostly idle)."""
        header = self.header(t_ns, sp.header.frame_id or "base")
        out = bare(OperationalSetpoint)       # every field set (conversions.bare): every period
        out._header, out._pose, out._velocity, out._acceleration = header, sp.pose, _ZERO_TWIST, _ZERO_ACCEL
        out._force, out._line = sp.force, 0
        self.setpoint_pub.publish(out)
        x_0, x_d = self._origin(), setpoint_pose(sp).tolist()
        self.state_pub.publish(self.message_factory(ControllerState)(
            header=header, controller="admittance_controller", enabled=False, names=list(AXES),
            reference=x_0, feedback=_ZEROS, error=[a - b for a, b in zip(x_d, x_0)],
            feedforward=_ZEROS, output=x_d, saturated=[False] * 6))
        self.report(DiagnosticStatus.OK, "idle", stamp_ns=t_ns)

    def _origin(self) -> list[float]:
        """The zone origin x_0 as floats, converted once per zone set (the idle state carries it
        every period; the message constructor copies it)."""
        zones = self.controller.zones
        if self._origin_of is not zones:
            self._origin_of, self._origin_floats = zones, zones.x_0.tolist()
        return self._origin_floats


def main(args=None):
    spin_node(AdmittanceControllerNode, args)


if __name__ == "__main__":
    main()

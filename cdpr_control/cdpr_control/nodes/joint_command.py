"""Node ``joint_command``: θ_d = IK{x_d + Σ offsets} - Δq_CFC (Fig. 3.4, (5.1), (5.10)) to the drives.

Subscribes ``setpoint``, ``cable_force_controller/state`` and one ``<name>/state``
(cdpr_msgs/ControllerState, ``output`` = the 6-vector offset) per entry of ``offset_inputs``
(``ospc`` by default; hybrid force control and load compensation join the same way, see
:mod:`cdpr_control.control.offset_inputs`; admittance control replaces x_d on ``setpoint`` instead),
synchronised per period in lockstep (every
declared input is awaited, so every declared offset node must run); free-running, an offset input
is used while younger than its deadline. For safety it also watches ``winch/state``,
``cable_forces``, ``platform/pose`` and ``forward_kinematics/diagnostics``. Publishes
``winch/command`` (sensor_msgs/JointState, position = θ_d [m]) and ``/diagnostics``.

Per offset input ``<name>``: parameters ``offsets.<name>.enabled`` and ``offsets.<name>.deadline``
[s], live; ``transfer_time`` [s] ramps every switch on or off (bumpless transfer), Δq_CFC too. At
start the first command is the measured θ, and the controllers' command is taken over along a
cosine over ``start_ramp`` [s] (:meth:`cdpr_control.control.joint_command.JointCommand.reset`).

``mode`` switches between the thesis's force control and the IK-only reference control
(section 2.3.2) at run time; the offsets and Δq_CFC are blended in and out over ``transfer_time``
(also when a controller reports itself enabled or disabled), and the command is rate-limited to
the drives' v_max. Faults of the safety monitor (non-finite input, position lag, FK not converged, stale
input, and optionally force limits) hold θ_d (braking on the path at ``a_brake``, see
:mod:`cdpr_control.control.joint_command`); the command is never NaN. The force watch
(:class:`cdpr_control.control.safety.ForceWatch`, ``force_watch``, on by default: a cable force beyond its
band for ``force_limit_time``, a force rate beyond ``max_force_rate``, a position error beyond
``max_position_lag``) holds for good: θ_d goes to the last safe command and stays there, reported
as ERROR with ``abort: True`` (the running program fails) until the service ``~/release_hold``
(std_srvs/Trigger) releases it. Also holding: a required input
(``setpoint``, ``cable_force_controller/state``) more than ``input_deadline`` periods behind the
winch state (its producer stopped: the command then comes on each winch state while braking,
instead of waiting for the dead input), and a set-point outside the wrench-feasible workspace: the
``force_distribution`` status INFEASIBLE for ``infeasible_periods`` periods in a row. A holding
report of a stale input, of the workspace or of the force watch on /diagnostics (ERROR, ``abort: True``) makes the
G-code interpreter fail its program; the other holds (lag, FK not converged) last while their fault does.
Invalid messages (lengths, non-finite values, frame) are dropped and reported (nodes/sync.py).
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import (CableForces, ControllerState, ForceDistribution, ForwardKinematicsDiagnostics,
    OperationalSetpoint)
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from cdpr_control.control.bumpless import Blend
from cdpr_control.force_distribution import Status
from cdpr_control.control.joint_command import A_BRAKE, JointCommand
from cdpr_control.control.params import default
from cdpr_control.control.offset_inputs import OffsetConfig, OffsetInputs, OffsetSample
from cdpr_control.control.safety import (FORCE_WATCH, STALE_INPUT, WORKSPACE, Fault, ForceWatch, SafetyConfig,
                                          SafetyMonitor, braking)
from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.conversions import pose_from_msg, setpoint_pose
from cdpr_control.ros.mode import mode_publisher, publish_mode
from cdpr_control.ros.parameters import ParameterSet, ParamSpec, declare
from cdpr_control.ros.qos import CONTROL
from cdpr_control.ros.sync import StampJumps, StampSync, input_problem, stamp_ns

OFFSET_INPUTS = ParamSpec("offset_inputs", ["ospc"], "controllers whose <name>/state output (6 values) is added "
                          "to x_d in the IK (5.1)/(5.10); each must publish every period", read_only=True)
DEFAULT_OFFSET = OffsetConfig()
_OK, _WARN, _ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR

# holding faults after which a program cannot go on (its input is gone, its path left the
# workspace, the force watch holds): reported with ``abort: True``, the G-code interpreter then
# fails the program; the others (lag, FK not converged, non-finite values) hold while they last
ABORTING = frozenset({STALE_INPUT, WORKSPACE, FORCE_WATCH})


def offset_params(name: str) -> list[ParamSpec]:
    """The live parameters of one offset input."""
    return [ParamSpec(f"offsets.{name}.enabled", DEFAULT_OFFSET.enabled, f"add the output of {name} to x_d"),
            ParamSpec(f"offsets.{name}.deadline", DEFAULT_OFFSET.deadline,
                      f"age of an active {name} state that holds the command [s]", range=(1e-4, 10.0))]


_S = SafetyConfig()   # the defaults live in the dataclass (one source of truth)
PARAMS = [
    ParamSpec("mode", default("joint_command", "mode"), "force_control: θ_d = IK(x_d + Σ offsets) - Δq_CFC; ik_only: θ_d = IK(x_d) "
              "(2.3.2), the offsets ramped out", choices=("force_control", "ik_only")),
    ParamSpec("v_max", 0.0, "rate limit of θ_d [m/s]; 0 = the robot's drive v_max", range=(0.0, 100.0)),
    ParamSpec("force_tolerance", _S.force_tolerance, "force beyond [f_min, f_max] tolerated before a fault [N]", range=(0.0, 1e5)),
    ParamSpec("hold_on_force_limit", _S.hold_on_force_limit, "a force-limit fault holds θ_d (else it is only reported)"),
    ParamSpec("max_position_lag", _S.max_position_lag, "position lag |r_d - r| that holds θ_d [m]", range=(0.0, 10.0)),
    ParamSpec("max_orientation_lag", _S.max_orientation_lag, "orientation lag |phi_d - phi| that holds θ_d [rad]", range=(0.0, 3.2)),
    ParamSpec("stale_timeout", _S.stale_timeout, "age of an input that holds θ_d [s]", range=(0.0, 10.0)),
    ParamSpec("force_watch", _S.force_watch, "the latched force watch: a runaway holds θ_d at the last safe command "
              "until ~/release_hold, and fails the running program"),
    ParamSpec("force_band", _S.force_band, "force watch: tolerance beyond [f_min, f_max] as a share of f_max - f_min [-]",
              range=(0.0, 10.0)),
    ParamSpec("force_limit_time", _S.force_limit_time, "force watch: time a cable force may stay beyond its band [s]",
              range=(0.0, 10.0)),
    ParamSpec("max_force_rate", _S.max_force_rate, "force watch: filtered |df/dt| that holds, in force ranges "
              "(f_max - f_min) per second [1/s]", range=(1e-3, 1e6)),
    ParamSpec("force_rate_filter", _S.force_rate_filter, "force watch: PT1 time constant of the force rate [s]",
              range=(0.0, 1.0)),
    ParamSpec("safe_history", _S.safe_history, "force watch: clean time after a command that makes its controller "
              "outputs the safe ones [s]", range=(1e-3, 10.0)),
    ParamSpec("a_brake", A_BRAKE, "deceleration of θ_d when holding (braking on the path) [m/s^2]", range=(1e-3, 1e4)),
    ParamSpec("infeasible_periods", 20, "periods in a row without a feasible force distribution (set-point outside "
              "the wrench-feasible workspace) that hold θ_d [-]", range=(1, 1_000_000)),
    ParamSpec("start_ramp", default("joint_command", "start_ramp"), "the drives take the controllers' command over from the "
              "lengths measured at start in this time: the first command's gap is ramped out along a cosine "
              "(docs/control.md, \"A start ramp\") [s]", range=(0.0, 10.0), read_only=True),
    ParamSpec("transfer_time", default("joint_command", "transfer_time"), "bumpless transfer: Δq_CFC and every offset "
              "input are blended in and out over this time on a mode switch or a controller enabled/disabled [s]",
              range=(0.0, 10.0)),
]


def parameters(robot, offset_inputs=OFFSET_INPUTS.default) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md), with the offsets.<name>.*
    of these offset inputs."""
    return [*PARAMS, OFFSET_INPUTS, *(spec for name in offset_inputs for spec in offset_params(name))]


class JointCommandNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("joint_command", **kwargs)
        self.names = [f"cable_{i + 1}" for i in range(self.robot.m)]
        self.command = JointCommand(self.robot, self.dt)
        self.blend_cfc = Blend(0.0, self.dt)        # bumpless transfer of Δq_CFC (offsets: self.offsets)
        self.monitor = SafetyMonitor()
        self.watch = ForceWatch(SafetyConfig(), self.dt)
        names = list(declare(self, OFFSET_INPUTS))
        self.offsets = OffsetInputs(names, self.dt, default("joint_command", "transfer_time"))
        self.offset_keys = [(name, f"offset:{name}") for name in names]     # (their input names)
        self.mode, self.mode_pub = None, mode_publisher(self)     # the OSPC and CFC nodes follow it
        self.params = ParameterSet(self, parameters(self.robot, names), self._validate, self._apply)
        self.latest: dict[str, object] = {}
        self.input_times: dict[str, float] = {}      # stamp [s] of each watched topic's message in latest
        self.infeasible = 0                          # periods in a row without a feasible f_d
        self._standing = False                       # a hold for a stale input has braked to a stand
        self._last_cycle_ns = -1                     # stamp of the newest period commanded
        self.watched_topics: dict[str, str] = {}
        self.watched_stamps = StampJumps(self.input_deadline, self.input_deadline * int(round(self.dt * 1e9)))
        for name, msg_type, topic in (("theta", JointState, "winch/state"), ("f", CableForces, "cable_forces"),
                                      ("x", PoseStamped, "platform/pose"),
                                      ("fk", ForwardKinematicsDiagnostics, "forward_kinematics/diagnostics"),
                                      ("fd", ForceDistribution, "force_distribution")):
            self.watched_topics[name] = topic
            self.create_subscription(msg_type, topic, self._keep(name, topic), CONTROL, adapted=True)
        self.publisher = self.create_publisher(JointState, "winch/command", CONTROL)
        inputs = {"setpoint": (OperationalSetpoint, "setpoint"),
                  "cfc": (ControllerState, "cable_force_controller/state")}
        inputs.update({f"offset:{name}": (ControllerState, f"{name}/state") for name in names})
        self.sync = StampSync(self, inputs, primary="cfc", callback=self._cycle, mode=self.sync_mode,
                              urgent=("cfc",),   # the command path (intraprocess.py)
                              optional=tuple(f"offset:{name}" for name in names),
                              sizes={"cfc": self.robot.m, **{f"offset:{name}": 6 for name in names}},
                              on_stale=self._hold_cycle)
        self.create_service(Trigger, "~/release_hold", self._on_release_hold)

    def _on_release_hold(self, request, response):
        """End the force watch's hold (an operator who has removed its cause); no step: θ_d goes from
        the held command to the controllers' along a cosine over START_RAMP, keeping the hold's
        tension correction (:meth:`cdpr_control.control.joint_command.JointCommand.update`)."""
        response.success = self.watch.fault is not None
        response.message = f"released: {self.watch.fault.message}" if response.success else "not holding"
        self.watch.release()
        return response

    def _keep(self, name: str, topic: str):
        m = self.robot.m

        def keep(msg):
            t = stamp_ns(msg)
            problem = input_problem(msg, m) or self.watched_stamps.check(name, t, self.sync.reference,
                                                                          self.sync.clock)
            if problem is not None:
                self.input_fault(topic, problem)
                return
            self.latest[name] = msg
            self.input_times[topic] = t * 1e-9       # (the safety monitor's staleness check)
            if name == "fd":
                self.infeasible = self.infeasible + 1 if msg.status == Status.INFEASIBLE else 0
            elif name == "theta":
                self.sync.advance(t)                 # the clock of the deadlines: a dead input holds
        return keep

    @staticmethod
    def _safety(v: dict) -> SafetyConfig:
        return SafetyConfig(**{k: v[k] for k in ("force_tolerance", "max_position_lag", "max_orientation_lag",
                                                 "stale_timeout", "hold_on_force_limit", "force_watch", "force_band",
                                                 "force_limit_time", "max_force_rate", "force_rate_filter",
                                                 "safe_history")})

    def _offset_configs(self, v: dict) -> dict[str, OffsetConfig]:
        return {n: OffsetConfig(enabled=v[f"offsets.{n}.enabled"], deadline=v[f"offsets.{n}.deadline"])
                for n in self.offsets.names}

    def _validate(self, v: dict) -> None:
        self._safety(v).validate()
        for name, config in self._offset_configs(v).items():
            config.validate(name)

    def _apply(self, v: dict) -> None:
        if v["mode"] != self.mode:
            publish_mode(self.mode_pub, v["mode"])
        self.mode = v["mode"]
        self._ok_message = f"ok ({self.mode})"       # the report of every good period
        self.command.v_max = v["v_max"] or self.robot.drive.v_max
        self.command.a_brake = v["a_brake"]
        self.infeasible_periods = int(v["infeasible_periods"])
        self.blend_cfc.set_transfer_time(v["transfer_time"])
        self.monitor = SafetyMonitor(self._safety(v))
        self.watch.configure(self._safety(v))
        self.offsets.configure(self._offset_configs(v), v["transfer_time"])

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        theta_msg = self.latest.get("theta")
        if theta_msg is None:
            return                                   # no measurement yet: nothing safe to start from
        if self.command.theta_d is None:
            self.command.reset(np.asarray(theta_msg.position), self.params.values["start_ramp"])
        x_d = setpoint_pose(msgs["setpoint"])
        force_control = self.mode == "force_control"
        samples = {name: self._offset_sample(msgs.get(key)) for name, key in self.offset_keys} \
            if force_control else {}
        offset, offset_faults = self.offsets.update(t_ns * 1e-9, samples)
        x = self._estimated_pose()
        faults = self._faults(t_ns, x_d, x) + offset_faults
        cfc = msgs["cfc"]
        s_cfc = self.blend_cfc.update(force_control and cfc.enabled)
        dq_cfc = s_cfc * np.asarray(cfc._output)
        forces = self._watch(x_d, offset, dq_cfc, faults, x)
        hold = any(f.holds for f in faults)
        theta_d = self.command.update(x_d, [offset], dq_cfc, hold=hold, safe=self.watch.safe if self.watch.fault else None,
                                      f=forces)                          # IK only at s_cfc = 0
        self._standing = False
        self._last_cycle_ns = max(self._last_cycle_ns, t_ns)
        self._publish(t_ns, theta_d, faults, hold)

    def _watch(self, x_d, offset, dq_cfc, faults: list, x=None):
        """One period of the force watch (x_d None: a period without a set-point, forces only), x the
        estimated pose (:meth:`_estimated_pose`); its fault first in ``faults`` (the report names it)
        -> the measured forces (or None)."""
        f_msg, fd_msg = self.latest.get("f"), self.latest.get("fd")
        f = None if f_msg is None else np.asarray(f_msg.f)
        f_d = None if fd_msg is None or len(fd_msg.f_d) != self.robot.m else np.asarray(fd_msg.f_d)
        # the position error only while no other fault holds: braking for one, the robot lags the
        # set-point by design
        x = None if x_d is None or braking(faults) else x
        c = self.robot.cable
        if x_d is None:
            tripped = self.watch.fault
        else:
            tripped = self.watch.update(f, c.f_min, c.f_max, x_d, offset, dq_cfc, f_d, x)
        if tripped is not None:
            faults.insert(0, tripped)
        return f

    def _hold_cycle(self, t_ns: int) -> None:
        """A period whose required input is stale (its producer stopped): brake on the path, so that
        the drives do not keep the last moving command. In lockstep the command comes on each winch
        state while braking and once standing; after that the simulator advances on its
        lockstep_timeout with the held command (answering every state would run the rest of the
        graph faster than it can follow); free-running it comes every period."""
        if self.command.theta_d is None or t_ns <= self._last_cycle_ns:
            return                                   # (this period has its command already)
        self._last_cycle_ns = t_ns
        moving = bool(self.command.velocity.any())
        faults = self._faults(t_ns, None, self._estimated_pose())
        forces = self._watch(None, None, None, faults)
        theta_d = self.command.update(None, hold=True, safe=self.watch.safe if self.watch.fault else None, f=forces)
        self._publish(t_ns, theta_d, faults, True,
                      send=moving or self.sync_mode == "latest" or not self._standing)
        self._standing = not moving

    def _publish(self, t_ns: int, theta_d, faults: list, hold: bool, send: bool = True) -> None:
        if send:
            self.publisher.publish(self.message_factory(JointState)(header=self.header(t_ns), name=self.names,
                                                                    position=theta_d))
        if faults:
            level = _ERROR if hold else _WARN
            self.report(level, "; ".join(f.message for f in faults[:3]) + ("; holding" if hold else ""),
                        {"holding": hold, "abort": hold and any(f.code in ABORTING for f in faults),
                         "faults": len(faults)}, stamp_ns=t_ns)
        elif self.command.held:
            self.report(_ERROR, "command outside the model (non-finite IK): holding", {"holding": True}, stamp_ns=t_ns)
        else:
            self.report(_OK, self._ok_message, stamp_ns=t_ns)

    @staticmethod
    def _offset_sample(msg) -> OffsetSample | None:
        """None for no message or an inactive one: OffsetInputs takes both alike (they add nothing)."""
        if msg is None or not msg._enabled:          # (the slots: three inputs every period)
            return None
        return OffsetSample(stamp_ns(msg) * 1e-9, True, np.asarray(msg._output))

    def _estimated_pose(self):
        """The forward kinematics' pose of the period (None before the first), converted once for
        the safety monitor and the force watch."""
        x_msg = self.latest.get("x")
        return None if x_msg is None else pose_from_msg(x_msg.pose)

    def _faults(self, t_ns: int, x_d, x):
        f_msg, fk = self.latest.get("f"), self.latest.get("fk")
        now = t_ns * 1e-9
        c = self.robot.cable
        faults = self.monitor.check(
            now, f=None if f_msg is None else np.asarray(f_msg.f), f_min=c.f_min, f_max=c.f_max,
            x_d=x_d, x=x, fk_converged=True if fk is None else fk.converged, input_times=self.input_times)
        sync = self.sync
        for name in sync.stale:
            faults.append(Fault(STALE_INPUT, f"stale input {sync.topics[name]}: older than input_deadline "
                                f"{sync.deadline} periods", True))
        if self.infeasible >= self.infeasible_periods:
            faults.append(Fault(WORKSPACE, f"set-point outside the wrench-feasible workspace: no feasible force "
                                f"distribution for {self.infeasible_periods} periods", True))
        return faults


def main(args=None):
    spin_node(JointCommandNode, args)


if __name__ == "__main__":
    main()

"""Node ``gcode_interpreter``: runs G-code programs (docs/gcode.md) through the jerk-limited
interpolator, thesis sections 2.3.2 and 5.1.2.

- action ``run_program`` (cdpr_msgs/RunProgram): one program at a time; feedback line, progress,
  state; result success or the first error as ``line:col: message ('text')`` with its line/column.
  Cancelling brakes jerk-limited on the path. A program starts at the current set-point.
- publishes ``setpoint`` (cdpr_msgs/OperationalSetpoint: x_d, xdot_d, xddot_d, F_d,0, line) every
  control period: with ``sync_mode = latest`` on a timer of the node clock (use_sim_time works),
  stamped on the period grid; with ``exact`` (lockstep) once per new ``winch/state``, with its
  stamp. Between programs it holds the last set-point (the robot's home at start-up).
- publishes ``program_status`` (cdpr_msgs/ProgramStatus) on change of state or line and every
  ``status_period``.
- services ``~/pause`` and ``~/resume`` (std_srvs/Trigger): jerk-limited stop on the path and
  continue; M0 (and M1 with ``optional_stop``) pause the same way.
- parameter M-codes and ``#<node.param> = value`` set a parameter of another node through its
  standard ``<node>/set_parameters`` service; the program waits for the answer (at most
  ``command_timeout``) and fails if it is refused. Numbers are converted to the remote parameter's
  type (integer <-> double) first, via ``<node>/get_parameter_types``.

- ``setpoint_source`` (read-only, e.g. ``admittance_controller``): while that node's
  ``<source>/state`` says ``enabled`` and no program runs, its ``<source>/setpoint`` is published
  as the set-point instead of the held one (hand guiding, docs/admittance.md); when it ends, its
  last pose is held, so a following program starts there. Programs are refused meanwhile. In
  lockstep the period t_k waits for the source's messages of t_k-1 (its set-point for t_k), at most
  ``input_deadline`` periods (then the source counts as stopped and the period runs without it).

Limit parameters apply to the next program, not to one that is running.

A program is parsed, checked against the workspace and planned on a thread of its own, so the loop
keeps running (and holding its set-point) while a long program is planned; other goals are refused
meanwhile. (Planning is Python and shares the interpreter's lock with the loop: a program of 10^6
lines slows the loop's periods while it is planned, it does not stop them.)

Faults fail the running program with the reason (result and ``program_status`` message), at once
(the set-point stops where it is; the joint command brakes the robot on the path): a report of the
``fault_source`` node on /diagnostics with ``abort: True`` (the joint command holds for a stale
input or a set-point outside the wrench-feasible workspace);
``winch/command`` more than twice ``input_deadline`` periods older than the winch state (the
command path stopped, the joint command too); in lockstep, no ``winch/state`` for
``state_timeout`` of wall time (not counted while the graph in this process still computes a period). A ``winch/state`` stamp that jumps more than
``input_deadline`` periods ahead (or back) is refused and reported unless the next one continues from it.
"""
from __future__ import annotations

import threading
import time

import numpy as np
from cdpr_msgs.action import RunProgram
from cdpr_msgs.msg import ControllerState, OperationalSetpoint, ProgramStatus
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameterTypes, SetParameters
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.clock import Clock as RclpyClock, ClockType
from rclpy.parameter import Parameter
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.program import GCodeError, ParameterCommand
from cdpr_control.motion.interpolation import AxisLimits, Interpolator, Limits, ProgramState, TERMINAL_STATES
from cdpr_control.model.kinematics import twist_from_pose_rates
from cdpr_control.model.memo import Memo
from cdpr_control.motion.program_check import check_program
from cdpr_control.ros.message_builders import builder

from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.adapted import attach_values
from cdpr_control.ros.conversions import (accel_to_msg, pose_from_msg, pose_to_msg, setpoint_values, twist_to_msg,
    vector3)
from cdpr_control.ros.intraprocess import IntraProcess
from cdpr_control.ros.parameters import ParameterSet, ParamSpec
from cdpr_control.ros.qos import CONTROL, DIAGNOSTICS, STATUS
from cdpr_control.ros.sync import StampJumps, stamp_ns

PARAMS = [
    ParamSpec("v_max", 0.5, "translational path velocity limit |xdot[0:3]| [m/s]", range=(1e-4, 10.0)),
    ParamSpec("a_max", 2.0, "translational acceleration limit |xddot[0:3]| [m/s^2]", range=(1e-3, 1e3)),
    ParamSpec("j_max", 20.0, "translational jerk limit [m/s^3]", range=(1e-2, 1e5)),
    ParamSpec("omega_max", 1.0, "limit of the Kardan angle rates |d(a,b,c)/dt| [rad/s]", range=(1e-4, 100.0)),
    ParamSpec("alpha_max", 5.0, "limit of the Kardan angle accelerations [rad/s^2]", range=(1e-3, 1e4)),
    ParamSpec("rot_jerk_max", 50.0, "limit of the Kardan angle jerks [rad/s^3]", range=(1e-2, 1e6)),
    ParamSpec("force_rate_max", 200.0, "rate limit of the force axes F_d,0 (U V W) [N/s]", range=(1e-3, 1e6)),
    ParamSpec("force_accel_max", 2000.0, "2nd-derivative limit of the force axes [N/s^2]", range=(1e-2, 1e8)),
    ParamSpec("force_jerk_max", 20000.0, "3rd-derivative limit of the force axes [N/s^3]", range=(1e-1, 1e10)),
    ParamSpec("optional_stop", False, "M1 pauses the program (else M1 is skipped)"),
    ParamSpec("command_timeout", 2.0, "wait for a parameter service of another node at most this long [s]",
              range=(0.0, 60.0)),
    ParamSpec("status_period", 0.1, "period of program_status and action feedback while running [s]",
              range=(1e-3, 10.0)),
    ParamSpec("frame_id", "base", "frame_id of the set-points", read_only=True),
    ParamSpec("payload", 0.0, "payload the workspace check of a program assumes [kg]", range=(0.0, 1e5)),
    ParamSpec("setpoint_source", "", "node whose <name>/setpoint replaces the held set-point while its "
              "<name>/state is enabled (hand guiding); '' = none", read_only=True),
    ParamSpec("source_timeout", 0.5, "free-running: age of the source's messages that ends forwarding [s]",
              range=(1e-3, 10.0)),
    ParamSpec("fault_source", "joint_command", "node whose report on /diagnostics with abort: True fails the running "
              "program; '' = none", read_only=True),
    ParamSpec("state_timeout", 5.0, "lockstep: wall time without a winch/state that fails the running program [s]",
              range=(1e-2, 600.0)),
]


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md)."""
    return list(PARAMS)

SOURCE_START_TOLERANCE = 1e-3   # m, rad: a source must take over at the held set-point (no jump)

_STATUS = {
    ProgramState.RUNNING: ProgramStatus.RUNNING,
    ProgramState.WAITING: ProgramStatus.RUNNING,
    ProgramState.PAUSING: ProgramStatus.STOPPING,
    ProgramState.CANCELLING: ProgramStatus.STOPPING,
    ProgramState.PAUSED: ProgramStatus.PAUSED,
    ProgramState.DONE: ProgramStatus.SUCCEEDED,
    ProgramState.CANCELLED: ProgramStatus.CANCELLED,
    ProgramState.FAILED: ProgramStatus.FAILED,
}


def limits_from(values: dict) -> Limits:
    """Interpolator limits from the node parameters; raises ValueError for non-positive ones."""
    return Limits(
        AxisLimits(values["v_max"], values["a_max"], values["j_max"]),
        AxisLimits(values["omega_max"], values["alpha_max"], values["rot_jerk_max"]),
        AxisLimits(values["force_rate_max"], values["force_accel_max"], values["force_jerk_max"]),
    )


class ParameterForwarder:
    """Sets one parameter of another node via get_parameter_types + set_parameters, asynchronously."""

    def __init__(self, node: CdprNode):
        self.node = node
        self._clients: dict[tuple[type, str], object] = {}
        self._pending: tuple[ParameterCommand, int, object] | None = None  # command, deadline ns, on_done

    def _client(self, srv_type, node_name: str, service: str):
        key = (srv_type, f"{node_name.rstrip('/')}/{service}")
        if key not in self._clients:
            self._clients[key] = self.node.create_client(srv_type, key[1])
        return self._clients[key]

    def send(self, command: ParameterCommand, timeout: float, on_done) -> None:
        """Start setting `command`; on_done(success, message) is called once, from the executor."""
        deadline = self.node.get_clock().now().nanoseconds + int(timeout * 1e9)
        self._pending = (command, deadline, on_done)
        self.poll()

    def poll(self) -> None:
        """Call every cycle: starts the request once the service is there, or gives up at the deadline."""
        if self._pending is None:
            return
        command, deadline, on_done = self._pending
        types = self._client(GetParameterTypes, command.node, "get_parameter_types")
        setter = self._client(SetParameters, command.node, "set_parameters")
        if types.service_is_ready() and setter.service_is_ready():
            self._pending = None
            if isinstance(command.value, (bool, str)):
                self._set(setter, command, command.value, on_done)
            else:
                future = types.call_async(GetParameterTypes.Request(names=[command.parameter]))
                future.add_done_callback(lambda f: self._set(setter, command, self._coerce(command.value, f), on_done))
        elif self.node.get_clock().now().nanoseconds >= deadline:
            self._pending = None
            on_done(False, f"node {command.node!r} is not running (no parameter service within "
                           f"command_timeout); start it, e.g. with the closed_loop graph")

    @staticmethod
    def _coerce(value, types_future):
        """An integer literal for a double parameter (and back) would be refused as a type change."""
        response = types_future.result()
        remote = response.types[0] if response is not None and response.types else ParameterType.PARAMETER_NOT_SET
        if remote == ParameterType.PARAMETER_DOUBLE:
            return float(value)
        if remote == ParameterType.PARAMETER_INTEGER and float(value).is_integer():
            return int(value)
        return value

    @staticmethod
    def _set(setter, command: ParameterCommand, value, on_done) -> None:
        request = SetParameters.Request(parameters=[Parameter(command.parameter, value=value).to_parameter_msg()])

        def answered(future):
            response = future.result()
            if response is None or not response.results:
                on_done(False, "no answer")
            else:
                on_done(response.results[0].successful, response.results[0].reason)

        setter.call_async(request).add_done_callback(answered)


class _ActiveProgram:
    """The program being executed and the action goal it belongs to."""

    def __init__(self, goal_handle, name: str, text: str, interp: Interpolator):
        self.goal_handle = goal_handle
        self.name = name
        self.line_count = text.count("\n") + 1
        self.interp = interp
        self.finished = Future()


class GCodeInterpreterNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("gcode_interpreter", **kwargs)
        self.limits = Limits()
        self.params = ParameterSet(self, parameters(self.robot), self._validate, self._apply)
        self.frame_id = self.params.values["frame_id"]
        self.q = np.r_[self.robot.home, np.zeros(3)]  # held set-point [x (6), F_d,0 (3)]
        self.xd = np.zeros(6)
        self.xdd = np.zeros(6)
        self.line = 0
        self.active: _ActiveProgram | None = None
        self.planning: str | None = None              # name of the program being planned
        self.last_status = ProgramStatus(state=ProgramStatus.IDLE)
        self._last_status_key = None
        self._last_status_ns = 0
        self.forwarder = ParameterForwarder(self)
        self.setpoint_pub = self.create_publisher(OperationalSetpoint, "setpoint", CONTROL)
        self.status_pub = self.create_publisher(ProgramStatus, "program_status", STATUS)
        self.action_server = ActionServer(self, RunProgram, "run_program", execute_callback=self._execute,
                                          goal_callback=self._on_goal, cancel_callback=self._on_cancel)
        self.create_service(Trigger, "~/pause", self._on_pause)
        self.create_service(Trigger, "~/resume", self._on_resume)
        self.source = self.params.values["setpoint_source"]
        self.source_msgs: dict[int, dict] = {}        # lockstep: stamp -> {"state": .., "setpoint": ..}
        self.source_latest: dict[str, object] = {}    # free-running: the newest of each
        self.guided: OperationalSetpoint | None = None  # the forwarded set-point of this period
        self._waiting_ns: int | None = None            # lockstep: a tick waiting for the source
        self._last_setpoint: OperationalSetpoint | None = None
        self._setpoint_body = Memo()     # see _setpoint_fields
        if self.source:
            # adapted: _forward only reads their fields, so the source's state payload (published every
            # period, guiding or not) is not built into a message for this node (issue 26)
            for key, msg_type in (("state", ControllerState), ("setpoint", OperationalSetpoint)):
                self.create_subscription(msg_type, f"{self.source}/{key}", self._on_source(key), CONTROL,
                                         adapted=True)
        self.state_jumps = StampJumps(self.input_deadline, self.input_deadline * int(round(self.dt * 1e9)))
        self._last_command_ns: int | None = None       # newest winch/command stamp
        self._last_state_wall = time.monotonic()
        self.fault_source = self.params.values["fault_source"]
        self.create_subscription(JointState, "winch/command", self._on_command, CONTROL, adapted=True)
        if self.fault_source:
            self.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, DIAGNOSTICS)
        if self.sync_mode == "exact":
            # lockstep: one period per new winch state, stamped like it (a deterministic data flow;
            # a timer on /clock could not produce the period of t = 0 before the loop has run)
            self._last_tick_ns = -1
            self.create_subscription(JointState, "winch/state", self._on_state, CONTROL, adapted=True)
            self.create_timer(0.1, self._state_watchdog, clock=RclpyClock(clock_type=ClockType.STEADY_TIME))
        else:
            self.timer = self.create_timer(self.dt, self._tick)  # node clock: sim time when use_sim_time
        self._publish_status(self._stamp_ns(), force=True)

    # ---- parameters --------------------------------------------------------------------------

    def _validate(self, values: dict) -> None:
        limits_from(values)

    def _apply(self, values: dict) -> None:
        self.limits = limits_from(values)
        self.values = values

    # ---- action ------------------------------------------------------------------------------

    def _on_goal(self, goal) -> GoalResponse:
        if self.guided is not None and not goal.dry_run:
            self.get_logger().warn(f"program {goal.name!r} refused: {self.source} is the set-point source")
            return GoalResponse.REJECT
        if goal.dry_run or (self.active is None and self.planning is None):
            return GoalResponse.ACCEPT
        busy = f"{self.active.name!r} is running" if self.active else f"{self.planning!r} is being planned"
        self.get_logger().warn(f"program {goal.name!r} refused: {busy}")
        return GoalResponse.REJECT

    def _on_cancel(self, goal_handle) -> CancelResponse:
        if self.active is not None and self.active.goal_handle is goal_handle:
            self.active.interp.cancel()
        return CancelResponse.ACCEPT

    def _plan(self, goal) -> Future:
        """Parse, check (in the wrench-feasible workspace) and plan ``goal`` on a thread of its own;
        the future's result is the Interpolator (or the planning error)."""
        start, limits, payload, optional_stop = self.q.copy(), self.limits, self.values["payload"], \
            self.values["optional_stop"]
        planned = Future()

        def plan() -> None:
            try:
                program = parse_gcode(goal.program, start_pose=start[:6], start_force=start[6:])
                check_program(program, self.robot, limits, payload)
                planned.set_result(Interpolator(program, limits, self.dt, wait_for_commands=True,
                                                optional_stop=optional_stop))
            except Exception as err:  # noqa: BLE001  (reported as the goal's result)
                planned.set_exception(err)

        threading.Thread(target=plan, name=f"plan {goal.name}", daemon=True).start()
        return planned

    async def _execute(self, goal_handle):
        goal = goal_handle.request
        result = RunProgram.Result()
        if not goal.dry_run and (self.active is not None or self.planning is not None):
            goal_handle.abort()                           # a second goal accepted in the same cycle
            busy = self.active.name if self.active is not None else self.planning
            result.message = f"{busy!r} is running"
            return result
        if not goal.dry_run:
            self.planning = goal.name
            self.get_logger().info(f"planning program {goal.name!r} ({goal.program.count(chr(10)) + 1} lines)")
        try:
            interp = await self._plan(goal)
        except GCodeError as err:
            first = err.diagnostics[0]
            goal_handle.abort()
            result.message, result.error_line, result.error_column = str(err), first.line, first.column
            return result
        except Exception as err:  # noqa: BLE001  (a bug in planning fails this goal, not the node)
            goal_handle.abort()
            result.message = f"planning failed: {type(err).__name__}: {err}"
            return result
        finally:
            if not goal.dry_run:
                self.planning = None
        if goal.dry_run:
            goal_handle.succeed()
            result.success, result.duration = True, interp.duration
            return result
        if goal_handle.is_cancel_requested:               # cancelled while it was planned
            goal_handle.canceled()
            result.message = "cancelled"
            return result
        self.active = active = _ActiveProgram(goal_handle, goal.name, goal.program, interp)
        self.get_logger().info(f"program {goal.name!r} started ({interp.duration:.3f} s planned)")
        await active.finished
        state = interp.state
        result.duration = interp.t
        result.success = state is ProgramState.DONE
        if state is ProgramState.DONE:
            goal_handle.succeed()
        elif state is ProgramState.CANCELLED:
            goal_handle.canceled()
            result.message = "cancelled"
        else:
            goal_handle.abort()
            result.message = interp.error
            result.error_line = interp.line
        self.get_logger().info(f"program {goal.name!r} ended: {state.value}")
        return result

    # ---- pause / resume ----------------------------------------------------------------------

    def _on_pause(self, request, response):
        response.success = self.active is not None and self.active.interp.pause()
        response.message = "pausing" if response.success else "no running program to pause"
        return response

    def _on_resume(self, request, response):
        response.success = self.active is not None and self.active.interp.resume()
        response.message = "resumed" if response.success else "no paused program to resume"
        return response

    # ---- the cycle ---------------------------------------------------------------------------

    def _stamp_ns(self) -> int:
        """Now on the control-period grid, so that lockstep nodes see the stamps they expect."""
        dt_ns = int(round(self.dt * 1e9))
        return int(round(self.get_clock().now().nanoseconds / dt_ns)) * dt_ns

    # ---- faults ------------------------------------------------------------------------------

    def _abort(self, reason: str, brake: bool = True) -> None:
        """Fail the running program with ``reason`` (braking on the path, or at once)."""
        active = self.active
        if active is None or not active.interp.abort(reason, brake):
            return
        self.get_logger().error(f"program {active.name!r} failed: {reason}")
        if not brake:                                   # no period will come to end it
            self._publish_status(self._last_stamp_ns(), force=True)
            self.active = None
            active.finished.set_result(active.interp.state)

    def _last_stamp_ns(self) -> int:
        return self._last_tick_ns if self.sync_mode == "exact" and self._last_tick_ns >= 0 else self._stamp_ns()

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        if self.active is None:
            return
        for status in msg.status:
            if status.level == DiagnosticStatus.ERROR and status.name.rsplit("/", 1)[-1] == self.fault_source \
                    and any(kv.key == "abort" and kv.value == "True" for kv in status.values):
                # at once: the joint command holds (braking on its own), the set-point is not followed
                self._abort(f"{self.fault_source} holds: {status.message}", brake=False)

    def _on_command(self, msg: JointState) -> None:
        stamp = stamp_ns(msg)
        if self._last_command_ns is None or stamp > self._last_command_ns:
            self._last_command_ns = stamp

    def _check_command_age(self, stamp: int) -> None:
        last = self._last_command_ns
        # twice the deadline: a stale input of the joint command is its to report (it then holds)
        if last is not None and stamp - last > 2 * self.input_deadline * self.dt * 1e9:
            self._abort(f"winch/command is older than twice input_deadline ({2 * self.input_deadline} periods): "
                        "the command path stopped", brake=False)

    def _state_watchdog(self) -> None:
        if self.active is None or IntraProcess.of(self.context).pending():
            # no program, or the graph in this process is still computing a period (slow, not
            # stopped: a composed lockstep run on a loaded machine; the simulator waits the same way)
            self._last_state_wall = time.monotonic()
        elif time.monotonic() - self._last_state_wall > self.values["state_timeout"]:
            self._abort(f"no winch/state for {self.values['state_timeout']:g} s (the simulator or the drives stopped)",
                        brake=False)

    def _clock_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _sim_clock_ns(self) -> int | None:
        """Simulated time once /clock runs (nothing may be stamped ahead of it), else None."""
        if not self.get_parameter("use_sim_time").value:
            return None
        now = self._clock_ns()
        return now if now > 0 else None

    def _on_state(self, msg: JointState) -> None:
        stamp = stamp_ns(msg)                           # (only the stamp is used here)
        problem = self.state_jumps.check("winch/state", stamp, self._clock_ns, self._sim_clock_ns)
        if problem is not None:
            self.input_fault("winch/state", problem)
            return
        self._last_state_wall = time.monotonic()
        if stamp > self._last_tick_ns:
            if self.source and self._last_tick_ns >= 0 and len(self.source_msgs.get(self._last_tick_ns, ())) < 2:
                if stamp - self._last_tick_ns <= self.input_deadline * self.dt * 1e9:
                    self._waiting_ns = stamp             # the source's set-point for this period is not there yet
                    return
                # the source stopped (e.g. behind a dead node): go on without it, else the loop never resumes
                self._waiting_ns = None
                self.report(DiagnosticStatus.WARN, f"stale input: {self.source}/setpoint older than input_deadline "
                            f"{self.input_deadline} periods: running without it", stamp_ns=stamp)
            self._tick_exact(stamp)
        elif stamp == self._last_tick_ns and self._last_setpoint is not None:
            # the simulator repeats a state until the period's command comes (its start-up handshake):
            # a node that subscribed after this period's set-point went out (one process per node,
            # discovery still running) gets it again, else the lockstep loop never starts
            self.setpoint_pub.publish(self._last_setpoint)

    def _tick_exact(self, stamp: int) -> None:
        previous, self._last_tick_ns = self._last_tick_ns, stamp
        self._tick(stamp, self.source_msgs.pop(previous, None) if self.source else None)
        for old in [s for s in self.source_msgs if s < previous]:
            del self.source_msgs[old]

    def _on_source(self, key: str):
        def receive(msg):
            if self.sync_mode == "latest":
                self.source_latest[key] = msg                          # only the newest matters
                return
            self.source_msgs.setdefault(stamp_ns(msg), {})[key] = msg
            if self._waiting_ns is not None and len(self.source_msgs.get(self._last_tick_ns, ())) == 2:
                waiting, self._waiting_ns = self._waiting_ns, None
                self._tick_exact(waiting)
        return receive

    def _source_now(self, stamp: int) -> dict | None:
        """Free-running: the newest source messages if both are younger than source_timeout."""
        msgs = self.source_latest
        if len(msgs) < 2 or stamp - min(stamp_ns(m) for m in msgs.values()) > self.values["source_timeout"] * 1e9:
            return None
        return msgs

    def _forward(self, msgs: dict | None) -> None:
        """Hand guiding: the source's set-point replaces the held one; its end keeps the last pose."""
        enabled = msgs is not None and msgs["state"].enabled and self.active is None
        if enabled and self.guided is None:
            jump = float(np.abs(pose_from_msg(msgs["setpoint"].pose) - self.q[:6]).max())
            if jump > SOURCE_START_TOLERANCE:            # it did not start from this set-point
                self.report(DiagnosticStatus.ERROR, f"{self.source} starts {1e3 * jump:.1f} mm/mrad away "
                            "from the set-point: not switching")
                return
        if enabled:
            self.guided = msgs["setpoint"]
            self.q[:6] = pose_from_msg(self.guided.pose)
            self.xd, self.xdd, self.line = np.zeros(6), np.zeros(6), 0
        elif self.guided is not None:
            self.guided = None                           # hold the last forwarded pose, at rest
            self.get_logger().info(f"{self.source} ended: holding {np.round(self.q[:6], 4).tolist()}")

    def _tick(self, stamp: int | None = None, source_msgs: dict | None = None) -> None:
        stamp = self._stamp_ns() if stamp is None else stamp
        active = self.active
        if active is not None:
            self._check_command_age(stamp)
            active = self.active
        if active is not None:
            self._step(active)
        if self.source:
            self._forward(source_msgs if self.sync_mode == "exact" else self._source_now(stamp))
        self._publish_setpoint(stamp)
        self._publish_status(stamp)
        if active is not None and active.interp.state in TERMINAL_STATES:
            self.active = None
            active.finished.set_result(active.interp.state)

    def _step(self, active: _ActiveProgram) -> None:
        sp = active.interp.step()
        self.q = np.r_[sp.x, sp.force]
        self.xd, self.xdd, self.line = sp.xd, sp.xdd, sp.line
        for command in sp.commands:
            self.get_logger().info(f"line {command.line}: {command.node}.{command.parameter} = {command.value!r}")
            self.forwarder.send(command, self.values["command_timeout"], active.interp.command_done)
        self.forwarder.poll()

    def _publish_setpoint(self, stamp: int) -> None:
        """The set-point of the period: where type adaptation is on, a payload carrying x_d, ẋ_d, ẍ_d
        as its subscribers convert them (conversions.setpoint_from_msg: nine nodes read them, one
        conversion serves them all)."""
        make = self.message_factory(OperationalSetpoint)
        if self.guided is not None:
            g = self.guided
            msg = make(header=self.header(stamp, self.frame_id), pose=g.pose, velocity=g.velocity,
                       acceleration=g.acceleration, force=vector3(self.q[6:]), line=0)
            values = setpoint_values(g.pose, g.velocity, g.acceleration)
        else:
            fields, values = self._setpoint_fields()
            msg = make(header=self.header(stamp, self.frame_id), **fields)
        attach_values(msg, values)
        self._last_setpoint = msg
        self.setpoint_pub.publish(msg)

    def _setpoint_fields(self) -> tuple[dict, tuple]:
        """The set-point's pose, twist, acceleration, force and line, and x_d, ẋ_d, ẍ_d as its
        subscribers read them (conversions.setpoint_values). While they do not change (holding a
        pose, a dwell) those of the last period are used again (subscribers do not modify what they
        receive), which spares the conversions."""
        q, xd, xdd, line = self.q, self.xd, self.xdd, self.line
        return self._setpoint_body((q.tobytes(), xd.tobytes(), xdd.tobytes(), line), _setpoint_body, q, xd, xdd, line)

    def _publish_status(self, stamp: int, force: bool = False) -> None:
        active = self.active
        if active is not None:
            interp = active.interp
            status = builder(ProgramStatus)(
                state=_STATUS[interp.state], program=active.name, line=int(interp.line), line_count=active.line_count,
                progress=float(interp.progress), elapsed=float(interp.t),
                remaining=float(interp.duration * (1.0 - interp.progress)), message=interp.error)
        else:
            status = self.last_status
        key = (status.state, status.line, status.message)
        period_ns = int(self.values["status_period"] * 1e9)
        if not force and key == self._last_status_key and stamp - self._last_status_ns < period_ns:
            return
        self._last_status_key, self._last_status_ns = key, stamp
        status.header = self.header(stamp, self.frame_id)
        self.last_status = status
        self.status_pub.publish(status)
        if active is not None:
            active.goal_handle.publish_feedback(
                RunProgram.Feedback(state=status.state, line=status.line, progress=status.progress))
        level = DiagnosticStatus.ERROR if status.state == ProgramStatus.FAILED else DiagnosticStatus.OK
        self.report(level, status.message or f"program {status.program!r}: state {status.state}", stamp_ns=stamp)

    def destroy_node(self):
        self.action_server.destroy()
        return super().destroy_node()


def _setpoint_body(q, xd, xdd, line) -> tuple[dict, tuple]:
    twist, accel = twist_from_pose_rates(q[:6], xd, xdd)
    fields = dict(pose=pose_to_msg(q[:6]), velocity=twist_to_msg(twist), acceleration=accel_to_msg(accel),
                  force=vector3(q[6:]), line=int(line))
    return fields, setpoint_values(fields["pose"], fields["velocity"], fields["acceleration"])


def main(args=None):
    spin_node(GCodeInterpreterNode, args)


if __name__ == "__main__":
    main()

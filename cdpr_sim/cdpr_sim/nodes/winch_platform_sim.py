"""Node ``winch_platform_sim``: the simulated cable robot behind the topics of a hardware driver.

Subscribes ``winch/command`` (sensor_msgs/JointState, position = theta_d [m]) and ``sim/wrench``
(geometry_msgs/WrenchStamped, a held external wrench, base frame, about the platform origin);
publishes ``winch/state`` (JointState: position theta [m], velocity thetadot [m/s], effort F_s
[N]), ``/clock``, the ground truth ``ground_truth/pose`` (PoseStamped), ``ground_truth/twist``
(TwistStamped, [v; omega] base frame), ``ground_truth/cable_forces`` (cdpr_msgs/CableForces at
the platform), ``ground_truth/external_wrench`` and, with obstacles, ``ground_truth/contact_wrench``
(WrenchStamped about the platform origin) and ``/diagnostics``. The surfaces (``floor``,
``wall``, ``cylinder``) are placed by parameters; their position and material are live. Services ``sim/set_payload``
(cdpr_msgs/SetPayload) and ``sim/apply_wrench`` (cdpr_msgs/ApplyWrench).

Time (``sync_mode``, shared with the control nodes): ``exact`` is lockstep, the node owns /clock
and advances one control period when the command stamped with the current time has arrived (a
controller copies the stamp of the winch/state it answers; a stamp older than the current period is
late: counted, no step, held unless older than the command held); after ``lockstep_timeout`` of
wall time it advances with the last command and counts a missed deadline (0 waits forever). Until the first command the state of
t = 0 is repeated every 0.5 s, so that late subscribers start the loop. Neither happens while
deliveries are queued in this process (a composed graph still computing the period is slow, not
stopped), so a composed lockstep run does not depend on the machine's load. ``latest`` runs free at
``realtime_factor`` times real time on a wall timer, holds the newest command and counts the
periods without a fresh one; it reports on /diagnostics the lateness of each step against its
wall-clock schedule (``step_lateness_*``) and the latency from publishing ``winch/state`` to
receiving the ``winch/command`` stamped like it (``command_latency_*``): p50/p99/max [us] of the
last second. Messages are stamped with simulation time in both modes (run the
other nodes with use_sim_time).

Start-up: the platform rests at ``initial_pose`` with the cable forces of the force distribution
at ``initial_tension_level``; with ``encoder_calibration = home_tension`` the encoders read
theta = IK{home} at home under that tension (thesis section 2.3.2), with ``none`` they read the
unstretched cable length.
"""
from __future__ import annotations

import time

import numpy as np
from cdpr_msgs.msg import CableForces
from cdpr_msgs.srv import ApplyWrench, SetPayload
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from rclpy.clock import Clock as RclpyClock, ClockType
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.intraprocess import has_subscribers
from cdpr_control.ros.lockstep import lockstep_watchdog
from cdpr_control.ros.conversions import pose_to_msg, twist_to_msg, wrench_from_msg, wrench_to_msg
from cdpr_control.ros.parameters import ParameterSet, ParamSpec
from cdpr_control.ros.qos import CONTROL
from cdpr_control.ros.sync import stamp_ns
from cdpr_control.ros.timing import DurationStats
from cdpr_control.control.safety import all_finite
from cdpr_control.ros.message_builders import builder

from cdpr_sim.contacts import ContactMaterial, Cylinder, Plane, PlatformShape, default_tool
from cdpr_sim.simulator import SimConfig, Simulator
from cdpr_sim.startup import startup_state

#: /clock as ROS publishes it (rclcpp::ClockQoS; rclpy's TimeSource subscribes best effort, depth 1)
CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
MAX_CATCH_UP = 20          # periods one free-running timer tick may advance
LATENCY_WINDOW = 1000      # free running: published states awaiting their command, at most


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md)."""
    tool_radius, tool_offset = default_tool(np.asarray(robot.b))
    return [
        ParamSpec("substeps", 1, "physics steps per control period (period / substeps <= 1 ms)", (1, 1000), read_only=True),
        ParamSpec("seed", 0, "seed of the sensor noise", (0, 2**31 - 1), read_only=True),
        ParamSpec("plant", SimConfig.plant, "mismatched: the robot's own parameters differ from the robot file "
                  "(cdpr_sim/plants/mismatch.yaml); nominal: the robot file (perfect model)",
                  choices=("mismatched", "nominal"), read_only=True),
        ParamSpec("plant_seed", SimConfig.plant_seed, "which mismatched robot", (0, 2**31 - 1), read_only=True),
        ParamSpec("cable_damping_time", 0.002, "Kelvin-Voigt damping time constant of the cables [s]", (0.0, 0.05), read_only=True),
        ParamSpec("friction", True, "pulley friction between force sensor and platform (3.30)-(3.43)", read_only=True),
        ParamSpec("noise_scale", 1.0, "force sensor noise as a multiple of the robot file's noise_std [-]", (0.0, 100.0), read_only=True),
        ParamSpec("encoder_counts", 2**20, "motor encoder counts per revolution; 0 = ideal", (0, 2**31 - 1), read_only=True),
        ParamSpec("ik_refresh_distance", 5e-3, "anchor motion before the pulley IK is re-evaluated [m]", (1e-6, 0.1), read_only=True),
        ParamSpec("initial_pose", robot.home.tolist(), "start pose x0 = [x, y, z, a, b, c] [m, rad]", read_only=True, size=6),
        ParamSpec("initial_tension_level", 0.5, "tension level of the start-up force distribution [0..1]", (0.0, 1.0), read_only=True),
        ParamSpec("encoder_calibration", "home_tension", "home_tension: theta = IK{home} at home under the start-up "
                  "tension (2.3.2); none: theta = unstretched length", choices=("home_tension", "none"), read_only=True),
        ParamSpec("floor", False, "a floor plane", read_only=True),
        ParamSpec("floor_height", float(robot.workspace_min[2]) - 0.5, "floor height [m]; live: moves the floor"),
        ParamSpec("wall", False, "a wall plane", read_only=True),
        ParamSpec("wall_point", [float(robot.workspace_max[0]) + 0.5, 0.0, 0.0], "a point of the wall [m]; live: moves the wall", size=3),
        ParamSpec("wall_normal", [-1.0, 0.0, 0.0], "outward wall normal [-]", read_only=True, size=3),
        ParamSpec("cylinder", False, "a cylinder (the oil barrel of section 5.1.3)", read_only=True),
        ParamSpec("cylinder_center", [0.0, 0.0, float(robot.workspace_min[2])], "cylinder centre [m]; live: moves the cylinder", size=3),
        ParamSpec("cylinder_axis", [0.0, 1.0, 0.0], "cylinder axis direction [-]", read_only=True, size=3),
        ParamSpec("cylinder_radius", 0.3, "cylinder radius [m]", (1e-4, 100.0), read_only=True),
        ParamSpec("cylinder_length", 0.9, "cylinder length [m]", (1e-4, 100.0), read_only=True),
        ParamSpec("contact_stiffness", 1e5, "obstacle stiffness per contact point [N/m]", (1.0, 1e10)),
        ParamSpec("contact_damping", 1e3, "obstacle damping per contact point [N s/m]", (0.0, 1e8)),
        ParamSpec("contact_friction", 0.5, "Coulomb friction coefficient of the obstacles [-]", (0.0, 10.0)),
        ParamSpec("platform_shape", "sphere", "platform contact shape: sphere (tool tip) or box (spanning b_i)",
                  choices=("sphere", "box"), read_only=True),
        ParamSpec("tool_radius", tool_radius, "tool tip sphere radius [m]", (1e-4, 10.0), read_only=True),
        ParamSpec("tool_offset", list(tool_offset), "tool tip centre in the platform frame [m]", read_only=True, size=3),
        ParamSpec("lockstep_timeout", 1.0, "wall time to wait for a command before advancing anyway [s]; 0 = forever",
                  (0.0, 3600.0)),
        ParamSpec("realtime_factor", 1.0, "free-running speed relative to real time [-]", (0.01, 1000.0)),
        ParamSpec("publish_ground_truth", True, "publish the ground_truth/* topics"),
    ]


def _validate(v: dict) -> None:
    """Beyond the declarations (sizes, finite values: ParameterSet): directions are not zero."""
    for name in ("wall_normal", "cylinder_axis"):
        if not np.linalg.norm(v[name]) > 0.0:
            raise ValueError(f"{name} must not be zero")


class WinchPlatformSimNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("winch_platform_sim", **kwargs)
        robot = self.robot
        self.params = ParameterSet(self, parameters(robot), _validate, self._apply)
        self.sim = self._build_simulator(self.params.values)
        self.names = [f"cable_{i + 1}" for i in range(robot.m)]
        self.period_ns = int(round(self.dt * 1e9))
        self.lockstep = self.sync_mode == "exact"
        # counters of the time protocol (reported on /diagnostics)
        self.missed_deadlines = 0
        self.late_commands = 0
        self.invalid_commands = 0
        self.overruns = 0
        self.got_command = False
        self.fresh_command = False
        self.theta_d = self.sim.output.theta.copy()     # hold the start until commanded
        self._command_stamp = -1                          # stamp of the command held in theta_d
        self.step_lateness = DurationStats("step_lateness")       # free running: wall clock vs schedule
        self.command_latency = DurationStats("command_latency")   # winch/state -> its winch/command
        self._states_sent: dict[int, float] = {}        # stamp -> perf_counter of recent winch/states

        self.state_pub = self.create_publisher(JointState, "winch/state", CONTROL)
        self.clock_pub = self.create_publisher(Clock, "/clock", CLOCK_QOS)
        self.truth_pubs = {
            "pose": self.create_publisher(PoseStamped, "ground_truth/pose", CONTROL),
            "twist": self.create_publisher(TwistStamped, "ground_truth/twist", CONTROL),
            "forces": self.create_publisher(CableForces, "ground_truth/cable_forces", CONTROL),
            "external": self.create_publisher(WrenchStamped, "ground_truth/external_wrench", CONTROL),
        }
        if self.sim.config.obstacles:
            self.truth_pubs["contact"] = self.create_publisher(WrenchStamped, "ground_truth/contact_wrench", CONTROL)
        # on the command path: in-process, delivered before the rest of the graph's period (intraprocess.py)
        self.create_subscription(JointState, "winch/command", self._on_command, CONTROL, urgent=True, adapted=True)
        self.create_subscription(WrenchStamped, "sim/wrench", self._on_wrench, CONTROL)
        self.create_service(SetPayload, "sim/set_payload", self._on_set_payload)
        self.create_service(ApplyWrench, "sim/apply_wrench", self._on_apply_wrench)

        self._wall_start = time.monotonic()
        self._waiting_since = self._wall_start
        self._last_handshake = -np.inf
        self._steps_at_start = 0
        # wall-clock timers: this node makes the simulation time, so it must not wait on it
        wall = RclpyClock(clock_type=ClockType.STEADY_TIME)
        if self.lockstep:
            self.create_timer(0.005, self._lockstep_watchdog, clock=wall)
        else:
            self.create_timer(self.dt, self._free_running_tick, clock=wall)
        self.create_timer(1.0, self._report, clock=wall)
        self._publish()

    # --- set-up ----------------------------------------------------------------------------

    def _apply(self, v: dict) -> None:
        self.lockstep_timeout = float(v["lockstep_timeout"])
        self.realtime_factor = float(v["realtime_factor"])
        self.publish_truth = bool(v["publish_ground_truth"])
        if hasattr(self, "sim"):                       # a live change of speed restarts the pacing
            self._wall_start = time.monotonic()
            self._steps_at_start = self.sim.steps
            self._place_obstacles(v)

    def _place_obstacles(self, v: dict) -> None:
        """Move the surfaces to their (live) parameters: contact is then made or lost physically."""
        material = ContactMaterial(v["contact_stiffness"], v["contact_damping"], v["contact_friction"])
        places = [(0.0, 0.0, v["floor_height"])] if v["floor"] else []
        places += [tuple(v["wall_point"])] if v["wall"] else []
        places += [tuple(v["cylinder_center"])] if v["cylinder"] else []
        for index, position in enumerate(places):
            self.sim.place_obstacle(index, position, material)

    def _build_simulator(self, v: dict) -> Simulator:
        robot = self.robot
        material = ContactMaterial(v["contact_stiffness"], v["contact_damping"], v["contact_friction"])
        obstacles = []
        if v["floor"]:
            obstacles.append(Plane.floor(v["floor_height"], material))
        if v["wall"]:
            obstacles.append(Plane(tuple(v["wall_point"]), tuple(v["wall_normal"]), material))
        if v["cylinder"]:
            obstacles.append(Cylinder(tuple(v["cylinder_center"]), tuple(v["cylinder_axis"]), v["cylinder_radius"],
                                      v["cylinder_length"], material))
        if v["platform_shape"] == "sphere":
            shape = PlatformShape("sphere", v["tool_radius"], tuple(v["tool_offset"]))
        else:
            shape = PlatformShape("box")
        config = SimConfig(
            period=self.dt, substeps=v["substeps"], seed=v["seed"], cable_damping_time=v["cable_damping_time"],
            ik_refresh_distance=v["ik_refresh_distance"], friction=v["friction"],
            noise_std=v["noise_scale"] * robot.sensor.noise_std, encoder_counts=v["encoder_counts"],
            platform_shape=shape, obstacles=tuple(obstacles), plant=v["plant"], plant_seed=v["plant_seed"])
        x0, theta0, offset = startup_state(robot, np.asarray(v["initial_pose"], dtype=float),
                                           v["initial_tension_level"], v["encoder_calibration"] == "home_tension",
                                           config)
        return Simulator(robot, config, x0=x0, theta0=theta0, encoder_offset=offset)

    # --- inputs ----------------------------------------------------------------------------

    def _on_command(self, msg: JointState) -> None:
        position = msg.position
        if len(position) != self.robot.m or not all_finite(position):
            self.invalid_commands += 1
            self.input_fault("winch/command", f"{len(position)} positions (need {self.robot.m} finite values)")
            return
        theta_d = np.asarray(position, dtype=float)
        stamp = stamp_ns(msg)
        t_ns = self.sim.steps * self.period_ns
        if stamp > t_ns:
            # a command answers a state published already: a later stamp is wrong (a clock fault,
            # a foreign publisher) and must neither drive the winches nor advance time
            self.invalid_commands += 1
            self.input_fault("winch/command", f"stamp {stamp * 1e-9:.3f} s is after the newest state "
                                              f"({t_ns * 1e-9:.3f} s)")
            return
        if stamp < self._command_stamp:
            # older than the command held (e.g. a second answer to a repeated start-up state):
            # it must not replace a newer one, or the run would depend on when the repeat came
            self.late_commands += 1
            return
        self.theta_d, self._command_stamp = theta_d, stamp
        self.got_command = True
        if not self.lockstep:
            sent = self._states_sent.pop(stamp, None)   # the first command answering that state
            if sent is not None:
                self.command_latency.add(time.perf_counter() - sent)
            self.fresh_command = True
        elif stamp == t_ns:
            self._advance()
        else:
            self.late_commands += 1                     # for a period already advanced: only held

    def _on_wrench(self, msg: WrenchStamped) -> None:
        if msg.header.frame_id not in ("", "base", "world"):
            self.get_logger().warn(f"sim/wrench must be in the base frame, got frame_id {msg.header.frame_id!r}",
                                   throttle_duration_sec=1.0)
            return
        try:
            self.sim.set_external_wrench(wrench_from_msg(msg.wrench))
        except ValueError as exc:
            self.get_logger().warn(str(exc), throttle_duration_sec=1.0)

    def _on_set_payload(self, request, response):
        p = request.payload
        J = np.array([[p.ixx, p.ixy, p.ixz], [p.ixy, p.iyy, p.iyz], [p.ixz, p.iyz, p.izz]])
        com = np.array([p.com.x, p.com.y, p.com.z])
        if not (np.isfinite(p.m) and p.m >= 0.0 and np.all(np.isfinite(J)) and np.all(np.isfinite(com))):
            response.success, response.message = False, "payload mass must be finite and >= 0, inertia and com finite"
        elif np.min(np.linalg.eigvalsh(J)) < -1e-12:
            response.success, response.message = False, "payload inertia must be positive semi-definite"
        else:
            response.total_mass = self.sim.set_payload(p.m, com, J)
            response.success, response.message = True, self.sim.payload_warning or ""
            if self.sim.payload_warning:
                self.get_logger().warn(self.sim.payload_warning)
            self._report()
        if not response.success:
            response.total_mass = self.sim.robot.platform.mass
        return response

    def _on_apply_wrench(self, request, response):
        try:
            self.sim.apply_pulse(wrench_from_msg(request.wrench),
                                 (request.point.x, request.point.y, request.point.z),
                                 request.shape or ApplyWrench.Request.SHAPE_STEP, request.duration, request.frequency)
            response.success, response.message = True, ""
        except ValueError as exc:
            response.success, response.message = False, str(exc)
        return response

    # --- time ------------------------------------------------------------------------------

    def _advance(self) -> None:
        self.sim.step(self.theta_d)
        self._waiting_since = time.monotonic()
        self._publish()

    _lockstep_watchdog = lockstep_watchdog      # (cdpr_control/ros/lockstep.py, shared with the graph benchmark)

    def _free_running_tick(self) -> None:
        due = int((time.monotonic() - self._wall_start) * self.realtime_factor / self.dt) + self._steps_at_start
        behind = due - self.sim.steps
        if behind > MAX_CATCH_UP:                       # too slow: let simulated time fall behind
            self.overruns += behind - MAX_CATCH_UP
            self._steps_at_start -= behind - MAX_CATCH_UP
            behind = MAX_CATCH_UP
        for _ in range(behind):
            if self.got_command and not self.fresh_command:
                self.missed_deadlines += 1
            self.fresh_command = False
            scheduled = self._wall_start + (self.sim.steps + 1 - self._steps_at_start) * self.dt / self.realtime_factor
            self.step_lateness.add(max(0.0, time.monotonic() - scheduled))
            self.sim.step(self.theta_d)
            self._publish()

    # --- outputs ---------------------------------------------------------------------------

    def _publish(self) -> None:
        out = self.sim.output
        t_ns = self.sim.steps * self.period_ns
        header = self.header(t_ns)
        self.clock_pub.publish(builder(Clock)(clock=header.stamp))
        if not self.lockstep:
            self._states_sent[t_ns] = time.perf_counter()
            if len(self._states_sent) > LATENCY_WINDOW:   # never answered: forget the oldest
                del self._states_sent[next(iter(self._states_sent))]
        self.state_pub.publish(self.message_factory(JointState)(header=header, name=self.names, position=out.theta,
                                                                velocity=out.thetadot, effort=out.F_s))
        if not self.publish_truth:
            return
        c = self.robot.cable
        pubs = self.truth_pubs
        # ground truth is for recording and watching: built only when someone takes it
        if has_subscribers(pubs["pose"]):
            pubs["pose"].publish(builder(PoseStamped)(header=header, pose=pose_to_msg(out.x)))
        if has_subscribers(pubs["twist"]):
            pubs["twist"].publish(builder(TwistStamped)(header=header, twist=twist_to_msg(out.xdot)))
        if has_subscribers(pubs["forces"]):
            pubs["forces"].publish(self.message_factory(CableForces)(header=header, f=out.f, f_min=c.f_min,
                                                                     f_max=c.f_max))
        if has_subscribers(pubs["external"]):
            pubs["external"].publish(builder(WrenchStamped)(header=header, wrench=wrench_to_msg(out.w_ext)))
        if "contact" in pubs and has_subscribers(pubs["contact"]):
            pubs["contact"].publish(builder(WrenchStamped)(header=header, wrench=wrench_to_msg(out.w_contact)))

    def _report(self) -> None:
        sim = self.sim
        wall = time.monotonic() - self._wall_start
        values = {"t": f"{sim.t:.3f}", "steps": sim.steps, "missed_deadlines": self.missed_deadlines,
                  "late_commands": self.late_commands, "invalid_commands": self.invalid_commands,
                  "overruns": self.overruns, "cable_overloads": sim.cables.overloads,
                  "realtime_factor": f"{(sim.steps - self._steps_at_start) * self.dt / wall:.2f}" if wall > 0 else "0"}
        if not self.lockstep:
            values.update(self.step_lateness.report())
            values.update(self.command_latency.report())
        warn = self.missed_deadlines or self.overruns or sim.cables.overloads or sim.payload_warning
        level = DiagnosticStatus.WARN if warn else DiagnosticStatus.OK
        mode = "lockstep" if self.lockstep else "free running"
        message = f"{mode}: {self.missed_deadlines} missed deadlines, {sim.cables.overloads} cable overloads"
        if sim.payload_warning:
            message += f"; {sim.payload_warning}"
        self.report(level, message, values, stamp_ns=sim.steps * self.period_ns, always=not self.lockstep)

    def destroy_node(self):
        self.sim.close()
        return super().destroy_node()


def main(args=None):
    spin_node(WinchPlatformSimNode, args)


if __name__ == "__main__":
    main()

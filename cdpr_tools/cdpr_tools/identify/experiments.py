"""Identification experiments recorded with the simulator into bags, as a real robot records them.

Topics and types are the graph's (docs/sim.md), fully qualified as a recorder names them:
``/winch/state`` (sensor_msgs/JointState: position theta, velocity thetadot, effort F_s),
``/winch/command`` (JointState: position theta_d), ``/ground_truth/cable_forces``
(cdpr_msgs/CableForces: the reference force at the platform that stands in for the extra sensor of
section 3.7.2), ``/ground_truth/pose`` (PoseStamped), ``/setpoint`` (cdpr_msgs/OperationalSetpoint:
x_d) and ``/joint_command/mode`` (std_msgs/String: ik_only). Header stamps and log times are sim time.
Every experiment takes ``seed`` (the sensor noise) and ``plant``, ``plant_seed`` (the simulated robot,
:mod:`cdpr_sim.plant`; default the simulator's, mismatched seed 1), independently.

The command of period k is stamped t_k and held over [t_k, t_k+1]; the state it causes is stamped
t_k+1, as in the lockstep graph (controllers answer the state of t_k with a command stamped t_k).

* :func:`record_friction_run`: IK-only reference control theta_d = IK{x_d} (section 2.3.2) along
  the identification trajectory of section 3.7.2, shortened: stop-and-go and alternating moves of
  0.5 .. 10 mm at 0.083 m/s along x, y, z, then alternating 30 mm moves at rising velocity.
* :func:`record_circle_run`: the circle of section 4.1.1 at constant angular velocity (mass).
* :func:`record_stiffness_run`: tension steps at home (force/elongation data for (2.16)).
* :func:`record_pulse_response`: a wrench pulse on the held platform, its free oscillation (4.8).
* :func:`record_drive_sweep`: a sine sweep on theta_d of one winch while the others hold the
  platform (section 3.3.1).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot

# fully qualified, as rosbag2 and the project's recorder (`cdpr launch --record`, `cdpr bag record`)
# name the graph's topics: the identification reads the bags a robot records
TOPIC_STATE = "/winch/state"
TOPIC_COMMAND = "/winch/command"
TOPIC_FORCES = "/ground_truth/cable_forces"
TOPIC_POSE = "/ground_truth/pose"
TOPIC_SETPOINT = "/setpoint"
TOPIC_MODE = "/joint_command/mode"     # std_msgs/String, latched: the controller that ran (figure titles)


def smooth_moves(waypoints, velocity, pause: float, dt: float) -> np.ndarray:
    """x_d samples (N, 6) through ``waypoints`` (k, 6): cosine-shaped moves, ``pause`` s at each.

    A move of length L takes 1.5 L / velocity (the cosine profile peaks at about ``velocity``);
    ``velocity`` is a number or one per move.
    """
    waypoints = np.asarray(waypoints, dtype=float)
    v = np.broadcast_to(np.asarray(velocity, dtype=float), (len(waypoints) - 1,))
    parts = [np.repeat(waypoints[:1], max(int(round(pause / dt)), 1), axis=0)]
    for a, b, vi in zip(waypoints[:-1], waypoints[1:], v):
        length = np.linalg.norm(b[:3] - a[:3])
        n = max(int(math.ceil(1.5 * length / vi / dt)), 1)
        s = 0.5 * (1.0 - np.cos(np.pi * np.arange(1, n + 1) / n))
        parts.append(a + s[:, None] * (b - a))
        parts.append(np.repeat(b[None], int(round(pause / dt)), axis=0))
    return np.concatenate(parts)


def friction_trajectory(home, amplitudes=(0.0005, 0.002, 0.01), velocity: float = 0.083, pause: float = 0.15,
                        fast_amplitude: float = 0.03, fast_velocities=(0.17, 0.35, 0.5), dt: float = 1e-3):
    """The reference trajectory of section 3.7.2 (shortened) about ``home``: x_d (N, 6).

    Per axis x, y, z: stop-and-go forward over ``amplitudes`` and back, then alternating moves of
    each amplitude; then alternating moves of ``fast_amplitude`` along x and z at ``fast_velocities``.
    """
    home = np.asarray(home, dtype=float)
    points, speeds = [home], []
    for axis in range(3):
        e = np.zeros(6)
        e[axis] = 1.0
        offset = 0.0
        for a in amplitudes:                                  # stop-and-go in one direction
            offset += a
            points.append(home + offset * e)
        for a in reversed(amplitudes):                        # and back
            offset -= a
            points.append(home + offset * e)
        for a in amplitudes:                                  # alternating
            points += [home + a * e, home - a * e, home]
        speeds += [velocity] * (len(points) - 1 - len(speeds))
    for v in fast_velocities:                                 # rising velocity
        for axis in (0, 2):
            e = np.zeros(6)
            e[axis] = fast_amplitude
            points += [home + e, home - e, home]
            speeds += [v] * 3
    return smooth_moves(points, speeds, pause, dt)


def sweep(duration: float, f_start: float, f_end: float, dt: float) -> np.ndarray:
    """Unit-amplitude exponential sine sweep from f_start to f_end Hz, samples at k dt, k = 0..N-1."""
    t = np.arange(int(round(duration / dt))) * dt
    rate = math.log(f_end / f_start) / duration
    return np.sin(2.0 * np.pi * f_start * (np.exp(rate * t) - 1.0) / rate)


class _Recorder:
    """Writes SimOutputs and commands on the graph's topics (messages imported on use: ROS types).

    The messages go the way the bag recorder of ``cdpr launch --record`` and ``cdpr bag record``
    sends them (:class:`cdpr_tools.bag.recorder.BagRecorder`): encoded by the generated CDR encoder
    of their type (:func:`cdpr_tools.bag.encode.serialize`), declared with the QoS the graph's
    publishers offer (``CONTROL``) and the type's hash, and written by the same writer child process
    (:class:`cdpr_tools.bag.writer_process.BagWriterProcess`, zstd chunks). What differs: the log
    time is the header stamp (the recorder's is its clock at reception, in a lockstep graph the same
    simulated time), and no DDS is involved: the simulator runs in this process.
    """

    def __init__(self, writer, robot):
        from cdpr_control.ros.mode import IK_ONLY
        from cdpr_control.ros.qos import CONTROL, STATUS
        from std_msgs.msg import String

        self.writer, self.robot, self.qos = writer, robot, CONTROL
        self.names = [f"cable_{i + 1}" for i in range(robot.m)]
        self._topics: dict[str, tuple[int, str]] = {}     # topic -> (writer index, type name)
        # the experiments command theta_d = IK{x_d} (or a hold): the graph's IK-only mode
        self._write(TOPIC_MODE, String(data=IK_ONLY), 0, STATUS)

    def _write(self, topic: str, msg, ns: int, qos=None) -> None:
        from cdpr_tools.bag.encode import serialize
        from cdpr_tools.message_convert import type_name_of

        if topic not in self._topics:
            type_name = type_name_of(msg)
            self._topics[topic] = (self.writer.add_topic(topic, type_name, qos or self.qos), type_name)
        index, type_name = self._topics[topic]
        self.writer.put((index, ns, serialize(msg, type_name), True))

    def _header(self, t: float):
        from cdpr_control.ros.message_builders import builder
        from std_msgs.msg import Header

        h = builder(Header)(frame_id="base")
        ns = int(round(t * 1e9))
        h.stamp.sec, h.stamp.nanosec = ns // 1_000_000_000, ns % 1_000_000_000
        return h, ns

    def state(self, out) -> None:
        from cdpr_control.ros.conversions import pose_to_msg
        from cdpr_control.ros.message_builders import builder
        from cdpr_msgs.msg import CableForces
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import JointState

        h, ns = self._header(out.t)
        c = self.robot.cable
        self._write(TOPIC_STATE, builder(JointState)(header=h, name=self.names, position=out.theta.tolist(),
                                                    velocity=out.thetadot.tolist(), effort=out.F_s.tolist()), ns)
        self._write(TOPIC_FORCES, builder(CableForces)(header=h, f=out.f.tolist(),
                                                      f_min=np.broadcast_to(c.f_min, out.f.shape).tolist(),
                                                      f_max=np.broadcast_to(c.f_max, out.f.shape).tolist()), ns)
        self._write(TOPIC_POSE, builder(PoseStamped)(header=h, pose=pose_to_msg(out.x)), ns)

    def command(self, t: float, theta_d, x_d=None) -> None:
        from cdpr_control.ros.conversions import pose_to_msg
        from cdpr_control.ros.message_builders import builder
        from cdpr_msgs.msg import OperationalSetpoint
        from sensor_msgs.msg import JointState

        h, ns = self._header(t)
        self._write(TOPIC_COMMAND, builder(JointState)(header=h, name=self.names, position=list(map(float, theta_d))),
                    ns)
        if x_d is not None:
            self._write(TOPIC_SETPOINT, builder(OperationalSetpoint)(header=h, pose=pose_to_msg(x_d)), ns)


def circle_trajectory(home, r_c: float = 0.1, frequency: float = 1.0, revolutions: float = 3.0,
                      ramp: float = 1.0, dt: float = 1e-3) -> np.ndarray:
    """x_d (N, 6) on the circle of section 4.1.1 (Fig. 4.2) in the xy plane, starting at ``home``.

    The centre is home - r_c e_x; the angular velocity rises smoothly to 2 pi frequency over
    ``ramp`` s, then stays constant for ``revolutions`` turns (the window of (4.2)-(4.3)).
    """
    omega = 2.0 * np.pi * frequency
    t_ramp = np.arange(int(round(ramp / dt))) * dt
    # thetadot_c = omega (1 - cos(pi t / ramp)) / 2 during the ramp
    angle_ramp = 0.5 * omega * (t_ramp - ramp / np.pi * np.sin(np.pi * t_ramp / ramp))
    t_const = np.arange(int(round(revolutions / frequency / dt)) + 1) * dt
    angle = np.concatenate([angle_ramp, 0.5 * omega * ramp + omega * t_const])
    x = np.repeat(np.asarray(home, dtype=float)[None], len(angle), axis=0)
    x[:, 0] += r_c * (np.cos(angle) - 1.0)
    x[:, 1] += r_c * np.sin(angle)
    return x


def _simulator(robot, seed: int, noise_std, level: float, payload=None, substeps: int = 1,
               plant: str = "mismatched", plant_seed: int = 1):
    """The simulator at rest at home under the QP forces of ``level``; payload (mass, c) carried from
    the start (tensed and encoders calibrated with it on, so the run starts in equilibrium).
    ``seed`` draws the sensor noise, ``plant_seed`` the mismatched robot (cdpr_sim.plant): two
    seeds, because one plant is identified from several runs with their own noise."""
    from cdpr_sim.simulator import SimConfig, Simulator
    from cdpr_sim.startup import startup_state

    loaded = robot if payload is None else robot.with_payload(*payload)
    config = SimConfig(seed=seed, noise_std=noise_std, friction=True, substeps=substeps, plant=plant,
                       plant_seed=plant_seed)
    x0, theta0, offset = startup_state(loaded, robot.home, level=level, calibrate_home=True, config=config)
    sim = Simulator(robot, config, x0=x0, theta0=theta0, encoder_offset=offset)
    if payload is not None:
        sim.set_payload(*payload)
    return sim


def record_run(robot, bag_path, commands, x_d, seed, noise_std, level, payload=None, before_step=None,
               substeps: int = 1, plant: str = "mismatched", plant_seed: int = 1) -> Path:
    """Simulate ``commands`` (N, m) (with set-points x_d (N, 6) or None) and record the bag.

    payload: (mass, centre of gravity) on the platform; before_step(sim, k): called before step k;
    substeps: physics steps per 1 ms period; seed: the sensor noise; plant, plant_seed: the
    simulated robot (:func:`cdpr_sim.plant.build_plant`; seed and plant_seed are independent).
    """
    from cdpr_tools.bag.writer_process import BagWriterProcess
    from cdpr_tools.progress import track

    with _simulator(robot, seed, noise_std, level, payload, substeps, plant, plant_seed) as sim:
        writer = BagWriterProcess(bag_path)
        try:
            rec = _Recorder(writer, robot)
            rec.state(sim.output)
            for k, theta_d in track(enumerate(commands), len(commands), f"simulating {writer.path.name}"):
                if before_step is not None:
                    before_step(sim, k)
                rec.command(sim.t, theta_d, None if x_d is None else x_d[k])
                rec.state(sim.step(theta_d))
        finally:
            writer.close()
        if writer.failed:
            raise OSError(f"recording {writer.path}: {writer.failed}")
        return writer.path


def record_friction_run(bag_path, robot="ipanema3_mini", seed: int = 1, noise_std=None, level: float = 0.5,
                        plant: str = "mismatched", plant_seed: int = 1, **trajectory) -> Path:
    """Record the friction identification run (IK-only control along :func:`friction_trajectory`)
    on the plant ``plant``, ``plant_seed`` (seed: the sensor noise)."""
    robot = load_robot(robot) if isinstance(robot, str) else robot
    x_d = friction_trajectory(robot.home, **trajectory)
    commands = np.array([inverse_kinematics(robot, x).q for x in x_d])
    return record_run(robot, bag_path, commands, x_d, seed, noise_std, level, plant=plant, plant_seed=plant_seed)


def record_circle_run(bag_path, robot="ipanema3_mini", seed: int = 1, noise_std=None, level: float = 0.5,
                      payload_mass: float = 0.0, payload_cog=(0.0, 0.0, 0.0), plant: str = "mismatched",
                      plant_seed: int = 1, **circle) -> Path:
    """Record the circle run of section 4.1.1 (IK-only control along :func:`circle_trajectory`).

    payload_mass [kg] at payload_cog [m, platform frame]: an additional load as in Fig. 4.1, (4.1).
    """
    robot = load_robot(robot) if isinstance(robot, str) else robot
    x_d = circle_trajectory(robot.home, **circle)
    commands = np.array([inverse_kinematics(robot, x).q for x in x_d])
    payload = (payload_mass, payload_cog) if payload_mass > 0.0 else None
    return record_run(robot, bag_path, commands, x_d, seed, noise_std, level, payload, plant=plant,
                      plant_seed=plant_seed)


def record_pulse_response(bag_path, robot="ipanema3_mini", wrench=(0.0, 0.0, -10.0, 0.0, 0.0, 0.0),
                          pulse: float = 0.004, rest: float = 0.2, duration: float = 0.6, seed: int = 1,
                          level: float = 0.5, payload_mass: float = 0.0, payload_cog=(0.0, 0.0, 0.0),
                          substeps: int = 10, plant: str = "mismatched", plant_seed: int = 1) -> Path:
    """Record the free oscillation of the platform for its eigenfrequency (section 4.3, (4.8)).

    The drives hold theta_d = IK{home} (no controller acts, as in the thesis' experiment); after
    ``rest`` s a rectangular ``wrench`` [N, N m] of ``pulse`` s (a knock on the platform, shorter than
    a period of the oscillation) hits the platform origin; ``duration`` s in all. ``substeps``
    physics steps per period: at 1 ms the explicit cable damping (zeta ~0.2 at 34 Hz on the Mini)
    raises the damped frequency by ~2 % over the continuous system.
    """
    robot = load_robot(robot) if isinstance(robot, str) else robot
    hold = inverse_kinematics(robot, robot.home).q
    commands = np.repeat(hold[None], int(round(duration / 1e-3)), axis=0)
    k_pulse = int(round(rest / 1e-3))

    def knock(sim, k):
        if k == k_pulse:
            sim.apply_pulse(wrench, shape="rectangle", duration=pulse)

    payload = (payload_mass, payload_cog) if payload_mass > 0.0 else None
    return record_run(robot, bag_path, commands, None, seed, None, level, payload, knock, substeps, plant,
                      plant_seed)


def record_stiffness_run(bag_path, robot="ipanema3_mini", levels=(0.75, 0.55, 0.35, 0.15), hold: float = 0.35,
                         ramp: float = 0.2, seed: int = 1, level: float = 0.95, plant: str = "mismatched",
                         plant_seed: int = 1) -> Path:
    """Record tension steps at home: theta_d = IK{home} - dq(f(level_j)) for each of ``levels``
    (QP forces (3.27)), ``ramp`` s cosine transitions, ``hold`` s at each: force/elongation data (2.16).
    The run starts tensed at ``level`` (a pre-load: the cables settle there, section 4.1.3) and
    steps down, so that no cable carries more than before and the steps see no settlement.
    plant, plant_seed: the simulator's plant (cdpr_sim.plant)."""
    from cdpr_sim.simulator import pretension_lengths
    from cdpr_sim.startup import startup_forces, startup_state

    robot = load_robot(robot) if isinstance(robot, str) else robot
    from cdpr_sim.simulator import SimConfig

    offset = startup_state(robot, robot.home, level, calibrate_home=True,
                           config=SimConfig(plant=plant, plant_seed=plant_seed))[2]
    targets = [pretension_lengths(robot, robot.home, startup_forces(robot, robot.home, lv)) + offset
               for lv in (level, *levels)]
    n_ramp, n_hold = int(round(ramp / 1e-3)), int(round(hold / 1e-3))
    parts = [np.repeat(targets[0][None], n_hold, axis=0)]
    for a, b in zip(targets[:-1], targets[1:]):
        s = 0.5 * (1.0 - np.cos(np.pi * np.arange(1, n_ramp + 1) / n_ramp))
        parts += [a + s[:, None] * (b - a), np.repeat(b[None], n_hold, axis=0)]
    return record_run(robot, bag_path, np.concatenate(parts), None, seed, None, level, plant=plant,
                      plant_seed=plant_seed)


def record_drive_sweep(bag_path, robot="ipanema3_mini", cable: int = 0, amplitude: float = 5e-4,
                       duration: float = 3.0, f_start: float = 0.5, f_end: float = 40.0, seed: int = 1,
                       level: float = 0.5, plant: str = "mismatched", plant_seed: int = 1) -> Path:
    """Record a sine sweep of ``amplitude`` m on theta_d of winch ``cable`` (0-based), the platform held."""
    robot = load_robot(robot) if isinstance(robot, str) else robot
    hold = inverse_kinematics(robot, robot.home).q            # the encoders read IK{home} at home
    commands = np.repeat(hold[None], int(round(duration / 1e-3)), axis=0)
    commands[:, cable] += amplitude * sweep(duration, f_start, f_end, 1e-3)
    return record_run(robot, bag_path, commands, None, seed, None, level, plant=plant, plant_seed=plant_seed)


def record_experiments(outdir, robot="ipanema3_mini", seed: int = 1, progress=print, plant: str = "mismatched",
                       plant_seed: int = 1) -> dict[str, Path]:
    """Record every identification experiment into ``outdir`` on one plant (``plant``, ``plant_seed``;
    ``seed``: the sensor noise): name -> bag path."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    bags = {}
    for name, record in (("friction", record_friction_run), ("drive_sweep", record_drive_sweep),
                         ("circle", record_circle_run), ("stiffness", record_stiffness_run),
                         ("pulse", record_pulse_response)):
        progress(f"recording {name} ...")
        bags[name] = record(outdir / name, robot=robot, seed=seed, plant=plant, plant_seed=plant_seed)
        progress(f"  {bags[name]}")
    return bags


def record_settlement_run(bag_path, robot="ipanema3", payload: float = 64.0, rest: float = 0.5, ramp: float = 0.3,
                          hold: float = 6.0, after: float = 1.0, seed: int = 1, level: float = 0.5,
                          plant: str = "mismatched", plant_seed: int = 1) -> Path:
    """Record the cable settlement under load (section 4.1.3): the drives hold IK{home} (IK-only
    control at standstill), ``payload`` kg is put on after ``rest`` s (cosine over ``ramp`` s),
    held ``hold`` s and taken off again (``after`` s more). The pose (``ground_truth/pose``, the
    laser tracker) shows the lasting elongation the forces do not (cdpr_tools.identify.settlement)."""
    robot = load_robot(robot) if isinstance(robot, str) else robot
    n_rest, n_ramp, n_hold = (int(round(v / 1e-3)) for v in (rest, ramp, hold))
    n = n_rest + 2 * n_ramp + n_hold + int(round(after / 1e-3))
    commands = np.repeat(inverse_kinematics(robot, robot.home).q[None], n, axis=0)

    def mass(k):
        s = np.clip(np.array([k - n_rest, n_rest + n_ramp + n_hold - k]) / n_ramp, 0.0, 1.0).min()
        return payload * 0.5 * (1.0 - np.cos(np.pi * s))

    def before_step(sim, k):
        if n_rest <= k <= n_rest + 2 * n_ramp + n_hold:
            sim.set_payload(mass(k))

    return record_run(robot, bag_path, commands, None, seed, None, level, before_step=before_step, plant=plant,
                      plant_seed=plant_seed)

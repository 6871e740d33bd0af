"""The winch and platform simulator: one control period per :meth:`Simulator.step` (no ROS here).

What is simulated (thesis sections 2.1.3, 3.3, 3.7):

* the platform as a pybullet rigid body under gravity, with the robot file's mass, centre of
  gravity and inertia, a payload that can change at run time, external wrenches and optional
  contact with planes and a cylinder (:mod:`cdpr_sim.contacts`);
* the cables as unilateral visco-elastic springs (2.14)-(2.17), (2.24) between the pulley leave
  points and the platform anchors (:mod:`cdpr_sim.cables`);
* the winches as position-controlled drives following theta_d, PT1 + dead time (3.10) or second
  order (5.11) as the robot file says (cdpr_sim.drive_models);
* the winch force sensors behind the pulleys: the forward pulley friction model (3.30)-(3.43)
  (cdpr_control.model.friction), the sensor line (3.29), noise and AD quantisation, and the encoders.

The physics runs on the plant's own parameters (:mod:`cdpr_sim.plant`), by default a robot that
differs from the robot file as a real one does (geometry, cable stiffness and settlement, friction,
drives, sensor lines); ``SimConfig(plant="nominal")`` makes the plant the robot file itself.

Cable lengths: theta is the winch's unstretched cable length and the elongation is
dq = IK{x} - theta (2.24), positive under tension (section 3.2). Encoders and commands may carry a
calibration offset (``encoder_offset``): encoder theta = unstretched length + offset. With the
offset of :func:`home_calibration_offset`, theta = IK{x} at the home pose under the start-up
tension, as the thesis sets up its encoders (section 2.3.2); with no offset theta is the
unstretched length itself.

Time: a control period of ``period`` seconds is ``substeps`` physics steps (period / substeps
<= 1 ms). theta_d is held over the period (zero-order hold); the outputs hold for the end of the
period. Forces come from the state at the start of each physics step, made linearly implicit over
the step (:meth:`cdpr_sim.cables.CableModel.implicit_wrench`: stable however stiff the loaded
cables, so a hard push or slack cables snapping taut add no energy); pybullet integrates the
platform semi-implicitly. Everything is deterministic for a given seed: the only random numbers are the
sensor noise, drawn from numpy's PCG64 generator.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pybullet

from cdpr_control.model import cable
from cdpr_control import kernels
from cdpr_sim.drive_models import DriveModel
from cdpr_control.model.friction import PulleyFriction, sensor_from_winch_force
from cdpr_control.model.kinematics import cross, inverse_kinematics
from cdpr_control.control.safety import all_finite

from cdpr_sim.cables import CableModel
from cdpr_sim.contacts import PlatformShape, add_obstacle, platform_collision_shape
from cdpr_sim.period import (winch_readings_kernel, compiled, measure as _measure_kernel,
    substep as _substep_kernel)
from cdpr_sim.plant import KINDS, Settlement, build_plant
from cdpr_sim.platform import PlatformBody, kardan_angles
from cdpr_sim.sensors import Encoder, ForceSensor
from cdpr_sim.wrench import WrenchPulse


_ZERO6 = np.zeros(6)
_ZERO6.setflags(write=False)
_NONE = np.zeros(0)        # array arguments of the compiled period that are not used
_NONE2 = np.zeros((0, 0))


@dataclass(frozen=True)
class SimConfig:
    """Simulator settings beyond the robot file (defaults in brackets are assumptions)."""

    period: float = 1e-3               # s, control period (one step); the field bus cycle of 2.3.2
    substeps: int = 1                  # physics steps per period; period / substeps <= 1 ms
    seed: int = 0                      # sensor noise seed
    cable_damping_time: float = 0.002  # s, Kelvin-Voigt tau_c [platform damping ratio ~5 %, 3.3.2]
    ik_refresh_distance: float = 5e-3  # m, anchor motion before the pulley IK is evaluated again
    friction: bool = True              # pulley friction between sensor and platform (3.30)-(3.43)
    friction_v_eps: float = 1e-7       # m/s, |thetadot| up to this counts as standstill (Dahl)
    noise_std: float | None = None     # N, force sensor noise; None: robot file
    sensor_gamma_1: tuple | None = None  # true sensor line slopes (3.29) per cable; None: calibration
    sensor_gamma_0: tuple | None = None  # true sensor line offsets (3.29) per cable; None: calibration
    encoder_counts: int = 2**20        # per motor revolution; 0 = ideal encoder [20 bit]
    platform_shape: PlatformShape = field(default_factory=PlatformShape)
    obstacles: tuple = ()              # contacts.Plane / contacts.Cylinder
    plant: str = "mismatched"          # mismatched: the plant's own parameters (cdpr_sim.plant); nominal: the robot file
    plant_seed: int = 1                # which mismatched robot (one seed, one robot)
    plant_file: str | None = None      # bounds of the mismatch; None: cdpr_sim/plants/mismatch.yaml

    def __post_init__(self):
        if not (math.isfinite(self.period) and self.period > 0.0):
            raise ValueError(f"period must be > 0 s, got {self.period}")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ValueError(f"substeps must be an integer >= 1, got {self.substeps}")
        if self.period / self.substeps > 1e-3 + 1e-12:
            raise ValueError(f"physics step period / substeps = {self.period / self.substeps} s "
                             "exceeds 1 ms: raise substeps")
        if self.plant not in KINDS:
            raise ValueError(f"plant must be one of {', '.join(KINDS)}, got {self.plant!r}")
        if not self.friction_v_eps >= 0.0:
            raise ValueError(f"friction_v_eps must be >= 0 m/s, got {self.friction_v_eps}")

    @property
    def dt(self) -> float:
        """Physics step [s]."""
        return self.period / self.substeps


@dataclass(slots=True)
class SimOutput:
    """Measurements and ground truth at time t (end of a control period).

    Measured (what a hardware driver publishes): theta (m,) encoder cable lengths [m], thetadot
    (m,) encoder difference over the period [m/s], F_s (m,) force sensor readings [N].
    Ground truth (the "laser tracker"): x (6,) platform pose, xdot (6,) twist [v; omega] (base
    frame), f (m,) cable forces at the platform [N], F_s_true (m,) sensor forces without noise and
    quantisation, theta_true (m,) drive positions (encoder coordinates, not quantised), beta (m,)
    wrap angles of the swivelling pulleys, w_ext (6,) external wrench about the platform origin,
    w_contact (6,) contact wrench about the platform origin.
    """

    t: float
    theta: np.ndarray
    thetadot: np.ndarray
    F_s: np.ndarray
    x: np.ndarray
    xdot: np.ndarray
    f: np.ndarray
    F_s_true: np.ndarray
    theta_true: np.ndarray
    beta: np.ndarray
    w_ext: np.ndarray
    w_contact: np.ndarray


def pretension_lengths(robot, x, f) -> np.ndarray:
    """Unstretched cable lengths theta (m,) that carry forces f (m,) at pose x: IK{x} - dq(f) (3.7)."""
    q = inverse_kinematics(robot, x).q
    return q - cable.elongation_from_force(robot, f, cable.total_free_length(robot, q))


def home_calibration_offset(robot, f) -> np.ndarray:
    """Encoder offset (m,) that reads theta = IK{home} with forces f at the home pose (2.3.2): dq(f)."""
    q = inverse_kinematics(robot, robot.home).q
    return cable.elongation_from_force(robot, f, cable.total_free_length(robot, q))


def plant_of(robot, config: "SimConfig"):
    """The plant (cdpr_sim.plant.Plant) a simulator of the nominal ``robot`` with ``config`` runs."""
    return build_plant(robot, config.plant, config.plant_seed, config.plant_file)


class Simulator:
    """Cable robot simulator for robot (cdpr_control.model.robot.Robot) with SimConfig ``config``.

    ``robot`` is the nominal robot file (the controller's model): the physics runs on the plant of
    ``config`` (``self.plant``, :mod:`cdpr_sim.plant`); the sensor readings apply the robot file's
    calibration. theta0 are the plant's unstretched lengths (see :func:`cdpr_sim.startup.startup_state`).

    Starts at rest at pose x0 (default robot.home) with unstretched cable lengths theta0 (default:
    IK{x0}, i.e. no tension) and encoder offset ``encoder_offset`` (default 0). ``output`` holds
    the SimOutput of time ``t``.

    ``fused`` (default True): a period runs as the laws :data:`sim_period` and :data:`sim_measure`,
    the compiled calls of :mod:`cdpr_sim.period` when the kernels are enabled, else the readable path
    of method calls and numpy expressions, the same numbers (tests/sim/test_sim_fused_period.py);
    False always runs the readable path.
    """

    fused: bool = True

    def __init__(self, robot, config: SimConfig = SimConfig(), x0=None, theta0=None, encoder_offset=None):
        self.nominal = robot
        self.plant = plant_of(robot, config)
        robot = self.plant.robot
        self.base_robot = robot
        self.robot = robot
        self.config = config
        self.m = robot.m
        self._pb = pybullet
        self._client = pybullet.connect(pybullet.DIRECT)
        pb, cid = self._pb, self._client
        pb.setTimeStep(config.dt, physicsClientId=cid)
        pb.setGravity(*map(float, robot.gravity), physicsClientId=cid)
        self._obstacles = [add_obstacle(pb, cid, o) for o in config.obstacles]
        shape = platform_collision_shape(pb, cid, config.platform_shape, np.asarray(robot.b))
        x0 = robot.home if x0 is None else x0
        self._body = PlatformBody(pb, cid, shape, robot.platform, x0, None)
        self.cables = CableModel(robot, config.cable_damping_time, config.ik_refresh_distance, config.dt)
        self._gravity = np.array(robot.gravity, dtype=float)
        self._thetadot_0 = np.empty(self.m)          # the drives' velocity at the start of a physics step
        self._u = np.empty(self.m)                    # the drive command of the fused period
        self._FT_step = np.empty(6)                   # the wrench of a physics step (fused period)
        self._A_next, self._d_next = np.empty((self.m, 6)), np.empty(self.m)   # linearisation for the next step
        self._r, self._R = np.empty(3), np.empty((3, 3))                       # and the platform's pose
        self.drives = DriveModel.from_robot(robot, config.dt, jit=compiled)
        self.encoder = Encoder.from_drive(robot.drive, config.encoder_counts)
        self.settlement = Settlement(self.plant.settlement_ratio, self.plant.settlement_time, robot.cable.k0,
                                     config.period, self.m)
        self._w_cont = np.zeros(6)
        self._pulse: WrenchPulse | None = None
        self._external = False            # a held wrench or a pulse is acting
        self.payload_warning: str | None = None     # why the payload is beyond the robot, see set_payload
        self.reset(x0, theta0, encoder_offset=encoder_offset)

    # --- set-up ----------------------------------------------------------------------------

    def reset(self, x0=None, theta0=None, xdot0=None, encoder_offset=None, seed: int | None = None) -> SimOutput:
        """Restart at time 0: pose x0, twist xdot0, unstretched lengths theta0, fresh noise and friction.

        Keeps the payload; clears external wrenches. Returns the output at t = 0.
        """
        robot, cfg = self.robot, self.config
        x0 = np.array(robot.home if x0 is None else x0, dtype=float)
        if x0.shape != (6,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"x0 must be 6 finite numbers, got {x0}")
        theta0 = inverse_kinematics(robot, x0).q if theta0 is None else np.array(theta0, dtype=float)
        self.encoder_offset = np.zeros(self.m) if encoder_offset is None else np.array(encoder_offset, dtype=float)
        for name, v in (("theta0", theta0), ("encoder_offset", self.encoder_offset)):
            if v.shape != (self.m,) or not np.all(np.isfinite(v)):
                raise ValueError(f"{name} must be {self.m} finite numbers, got {v}")
        self.t = 0.0
        self.steps = 0
        self._rng = np.random.Generator(np.random.PCG64(cfg.seed if seed is None else seed))
        plant = self.plant
        self.sensor = ForceSensor(self.nominal.sensor, self.m, self._rng,
                                  plant.gamma_1 if cfg.sensor_gamma_1 is None else cfg.sensor_gamma_1,
                                  plant.gamma_0 if cfg.sensor_gamma_0 is None else cfg.sensor_gamma_0, cfg.noise_std)
        self.settlement.s[:] = 0.0
        self.settlement.f_settled = None             # settled to the forces of the first measurement
        self.friction = PulleyFriction.from_robot(robot, theta0, cfg.friction_v_eps, jit=compiled)
        self.drives.reset(theta0)
        self._body.set_state(x0, xdot0)
        self.cables.refresh(x0)
        self._w_cont = np.zeros(6)
        self._pulse = None
        self._external = False
        self._theta_enc_prev = self.encoder.read(theta0 + self.encoder_offset)
        self._theta_prev = self.drives.theta
        # the sensor pulley's gain 1 - cos beta_1 (3.36) of sensor_from_winch_force and of the
        # friction kernel (kernels.friction), the same numbers (numpy's cos)
        self._gain = np.broadcast_to(1.0 - np.cos(np.asarray(self.robot.sensor.beta_1, dtype=float)), (self.m,)).copy()
        self._friction_gain = float(1.0 - np.cos(self.friction.beta_1))
        self.output = self._measure()
        return self.output

    def set_payload(self, mass: float, center_of_gravity=(0.0, 0.0, 0.0), inertia=None) -> float:
        """Attach a payload rigidly to the platform (replacing the previous one; mass 0 removes it).

        center_of_gravity (3,) in the platform frame [m], inertia (3, 3) about it [kg m^2] (None:
        a point mass), see Robot.with_payload. The platform keeps its pose and twist. Returns the
        total mass [kg].

        A payload the robot cannot hold is simulated all the same (an overload is a fault to test
        against) but ``payload_warning`` then says why: no cable forces within [f_min, f_max] hold
        the loaded platform at its current pose (2.39)-(2.40), with the capacity there.
        """
        robot = self.base_robot.with_payload(mass, center_of_gravity, inertia)
        self._body.set_mass_properties(robot.platform)      # same pose and twist: forces unchanged
        self.robot = robot
        self.payload_warning = self._payload_warning(mass)
        return robot.platform.mass

    def _payload_warning(self, mass: float) -> str | None:
        if mass <= 0.0:
            return None
        from cdpr_control.force_distribution import wrench_feasible     # a service call: import on use
        from cdpr_control.motion.program_check import payload_capacity
        from cdpr_control.model.workspace import static_problem
        robot, base = self.robot, self.base_robot
        x, _ = self._body.pose_and_twist()
        AT, w = static_problem(robot, x[None])
        c = robot.cable
        if wrench_feasible(AT, w, c.f_min, c.f_max)[0]:
            return None
        capacity = payload_capacity(base, x)
        return (f"payload {mass:g} kg is beyond what the robot can hold: no cable forces within [f_min, f_max] = "
                f"[{np.min(c.f_min):g}, {np.max(c.f_max):g}] N hold {robot.platform.mass:g} kg at "
                f"x = {np.round(x[:3], 3).tolist()} m (capacity there {capacity:.3g} kg of payload); "
                "simulating the overload")

    def set_external_wrench(self, w) -> None:
        """A held external wrench (6,) [N, N m] on the platform, base frame, about the platform origin."""
        w = np.array(w, dtype=float)
        if w.shape != (6,) or not np.all(np.isfinite(w)):
            raise ValueError(f"external wrench must be 6 finite numbers, got {w}")
        self._w_cont = w
        self._external = self._pulse is not None or bool(w.any())

    def apply_pulse(self, wrench, point=(0.0, 0.0, 0.0), shape: str = "step", duration: float = 0.0,
                    frequency: float = 0.0) -> WrenchPulse:
        """Start a wrench pulse now (replacing the active one), see :mod:`cdpr_sim.wrench`."""
        self._pulse = WrenchPulse(tuple(map(float, wrench)), tuple(map(float, point)), shape,
                                  float(duration), float(frequency), self.t)
        self._external = True
        return self._pulse

    def clear_pulse(self) -> None:
        self._pulse = None
        self._external = bool(self._w_cont.any())

    def place_obstacle(self, index: int, position=None, material=None) -> None:
        """Move obstacle ``index`` of ``config.obstacles`` at run time: a plane to pass through
        ``position`` (3,), a cylinder to be centred there [m, base frame]; optionally a new
        ContactMaterial. Contact is then made or lost by the physics, not by a script."""
        body = self._obstacles[index]
        pb, cid = self._pb, self._client
        if position is not None:
            position = np.asarray(position, dtype=float)
            if position.shape != (3,) or not np.all(np.isfinite(position)):
                raise ValueError(f"obstacle position must be 3 finite numbers, got {position}")
            _, orientation = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
            pb.resetBasePositionAndOrientation(body, position.tolist(), orientation, physicsClientId=cid)
        if material is not None:
            pb.changeDynamics(body, -1, contactStiffness=material.stiffness, contactDamping=material.damping,
                              lateralFriction=material.friction, physicsClientId=cid)

    def close(self) -> None:
        if self._client is not None:
            self._pb.disconnect(physicsClientId=self._client)
            self._client = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # --- stepping --------------------------------------------------------------------------

    def step(self, theta_d) -> SimOutput:
        """Advance one control period with the drive command theta_d (m,) (encoder coordinates)."""
        if self.fused:
            td = np.asarray(theta_d, dtype=float)
            if td.shape == (self.m,):            # else the readable path: broadcasts or refuses
                return sim_period(self, td, theta_d)
        return self._step_readable(theta_d)

    def _step_readable(self, theta_d, given=None) -> SimOutput:
        """:meth:`step` as method calls and numpy expressions (``given``: unused, the fused path's
        original argument)."""
        u = np.asarray(theta_d, dtype=float) - self.encoder_offset
        if u.shape != (self.m,) or not all_finite(u):       # (a fifth of isfinite().all() on m values)
            raise ValueError(f"theta_d must be {self.m} finite numbers, got {theta_d if given is None else given}")
        cfg, body, cables, drives, pb, cid = self.config, self._body, self.cables, self.drives, self._pb, self._client
        dt = cfg.dt
        t = self.t
        for i in range(cfg.substeps):
            if i == 0:                                   # the state of _measure: forces known
                f, A, d, r, R = self._pending
            else:
                r, R, v, omega = body.state()
                f, _, _, _ = cables.wrench(r, R, v, omega, drives.theta + self.settlement.s, drives.thetadot)
                A, d = cables.linearisation()
            w = self._external_wrench(t, R) if self._external else _ZERO6
            # the contact wrench of the last period belongs to the platform's load: at rest in contact
            # the implicit step then applies the cables' own forces (no predicted motion)
            w_load = w + self._w_contact if self._obstacles else w
            thetadot_0 = self._thetadot_0
            thetadot_0[:] = drives.thetadot
            drives.step(u)                               # the drives do not feel the cable forces
            F, T = cables.implicit_wrench(f, A, d, thetadot_0, drives.thetadot, body.mass, body.c, body.inertia, R,
                                          self._gravity, w_load)
            if self._external:
                F, T = F + w[:3], T + w[3:]
            body.apply(F, T, r)
            pb.stepSimulation(physicsClientId=cid)
            t += dt
        return self._end_period()

    def _step_fused(self, theta_d: np.ndarray, given) -> SimOutput:
        """:meth:`step` with the arithmetic after the pybullet calls in compiled calls (period.substep,
        period.measure): the same numbers. ``given``: theta_d as the caller passed it (for the error)."""
        cfg, body, cables, drives, pb, cid = self.config, self._body, self.cables, self.drives, self._pb, self._client
        dt = cfg.dt
        t = self.t
        f, A, d, r, R = self._pending
        FT = self._FT_step
        for i in range(cfg.substeps):
            if i > 0:
                r, R, v, omega = body.state()
                f, _, _, _ = cables.wrench(r, R, v, omega, drives.theta + self.settlement.s, drives.thetadot)
                A, d = cables.linearisation()
            w = self._external_wrench(t, R) if self._external else _ZERO6
            w_load = w + self._w_contact if self._obstacles else w
            # self._external read after _external_wrench, which may end a pulse (as the readable path)
            theta = np.empty(self.m)
            head, dropped = _substep_kernel(
                theta_d, self.encoder_offset, self._u, *drives.step_arguments(), self._thetadot_0, f, A, d, cables.step,
                body.mass, body.c, body.inertia, R, self._gravity, w_load, w, self._external, FT, theta)
            if head < 0:
                raise ValueError(f"theta_d must be {self.m} finite numbers, got {given}")
            drives.stepped(head, theta)
            cables.slackened += dropped
            body.apply_wrench(FT, r)
            pb.stepSimulation(physicsClientId=cid)
            t += dt
        return self._end_period()

    def _end_period(self) -> SimOutput:
        """The period done (both step paths): its count, time and measured outputs."""
        self.steps += 1
        self.t = self.steps * self.config.period
        self.output = self._measure()
        return self.output

    def _external_wrench(self, t: float, R) -> np.ndarray:
        w = self._w_cont
        if self._pulse is not None:
            w = w + self._pulse.wrench_about_origin(t, R)
            if self._pulse.finished(t):
                self.clear_pulse()
        return w

    def _measure(self) -> SimOutput:
        """Outputs at the current time; also prepares the forces for the next physics step."""
        settlement = self.settlement
        if self.fused and (settlement.ratio == 0.0 or settlement.f_settled is not None):
            return sim_measure(self)
        return self._measure_readable()

    def _measure_readable(self) -> SimOutput:
        """:meth:`_measure` as method calls and numpy expressions."""
        body, cables, drives, period = self._body, self.cables, self.drives, self.config.period
        r, R, v, omega = body.state()
        theta = drives.theta
        theta_u = theta + self.settlement.s                  # unstretched length incl. settlement
        f, _, _, _ = cables.wrench(r, R, v, omega, theta_u, drives.thetadot)
        x = np.concatenate((r, kardan_angles(R)))
        if cables.needs_refresh():
            cables.refresh(x)
            f, _, _, _ = cables.wrench(r, R, v, omega, theta_u, drives.thetadot)
        f = f.copy()
        self.settlement.update(f, cable.total_free_length(self.robot, theta_u))   # acts from the next step
        A, d = cables.linearisation()
        self._pending = (f, A.copy(), d.copy(), r, R)
        w_ext = self._external_wrench(self.t, R) if self._external else _ZERO6
        # friction and sensors run at the control rate with the period's mean winch velocity
        thetadot, theta_true, theta_enc, thetadot_enc = winch_readings_kernel(
            theta, self._theta_prev, self.encoder_offset, self.encoder.resolution, self._theta_enc_prev, 1.0 / period)
        self._theta_prev = theta
        self._theta_enc_prev = theta_enc
        if self.config.friction:
            F_s_true = friction_sensor_force(self.friction, f, theta, thetadot, cables.beta)
        else:
            F_s_true = sensor_from_winch_force(f, self.robot.sensor.beta_1)
        self._w_contact = self._contact_wrench(r) if self._obstacles else _ZERO6
        return SimOutput(
            t=self.t, theta=theta_enc, thetadot=thetadot_enc, F_s=self.sensor.read(F_s_true),
            x=x, xdot=np.concatenate((v, omega)), f=f,
            F_s_true=F_s_true, theta_true=theta_true, beta=cables.beta, w_ext=w_ext,
            w_contact=self._w_contact,
        )

    def _measure_fused(self) -> SimOutput:
        """:meth:`_measure` with the arithmetic after the pybullet reads in one compiled call
        (period.measure; a second one after a pulley IK refresh): the same numbers."""
        body, cables, drives, settlement, cfg = self._body, self.cables, self.drives, self.settlement, self.config
        pos, rot, lin, ang = body.raw_state()
        theta = drives.theta
        noise = self.sensor.next_noise()
        friction = self.friction
        dahl = friction.dahl
        f_settled = _NONE if settlement.f_settled is None else settlement.f_settled
        check = cables.refresh_distance
        tol, iterations = 1e-12, 50               # those of kernels.friction_sensor_force (the readable path)
        m, empty = self.m, np.empty
        r, R = self._r, self._R           # the next step's (self._pending), then overwritten
        x, xdot, f, theta_true, theta_enc, thetadot_enc, F_s_true, F_s = (
            empty(6), empty(6), empty(m), empty(m), empty(m), empty(m), empty(m), empty(m))
        while True:
            alpha_t, gamma_t = friction.series.tables(cables.beta) if cfg.friction else (_NONE2, _NONE2)
            status, overload, cables.moved = _measure_kernel(
                pos, rot, lin, ang, theta, settlement.s, drives.thetadot, check, *cables.wrench_arguments(),
                self.robot.l_0, settlement.ratio, f_settled, settlement.k0, settlement.alpha, self._A_next,
                self._d_next, self._theta_prev, self.encoder_offset, self.encoder.resolution, self._theta_enc_prev,
                1.0 / cfg.period, cfg.friction, alpha_t, gamma_t, dahl.sigma, dahl.v_eps, dahl.state, tol, iterations,
                self._friction_gain, self._gain, _NONE if noise is None else noise, noise is not None,
                *self.sensor.quantiser(), r, R, x, xdot, f, theta_true, theta_enc, thetadot_enc, F_s_true, F_s)
            if overload:
                cables.overloads += 1
            if status == 0:
                break
            cables.refresh(x)                     # then the forces again, without a second check
            check = -1.0
        self._pending = (f, self._A_next, self._d_next, r, R)
        w_ext = self._external_wrench(self.t, R) if self._external else _ZERO6
        self._theta_prev = theta
        self._theta_enc_prev = theta_enc
        self._w_contact = self._contact_wrench(r) if self._obstacles else _ZERO6
        return SimOutput(
            t=self.t, theta=theta_enc, thetadot=thetadot_enc, F_s=F_s, x=x, xdot=xdot, f=f, F_s_true=F_s_true,
            theta_true=theta_true, beta=cables.beta, w_ext=w_ext, w_contact=self._w_contact)

    def _contact_wrench(self, r) -> np.ndarray:
        """Sum of the contact forces on the platform (last physics step) about its origin."""
        w = np.zeros(6)
        for c in self._pb.getContactPoints(bodyA=self._body.body, physicsClientId=self._client):
            n, d1, d2 = np.array(c[7]), np.array(c[11]), np.array(c[13])
            F = c[9] * n + c[10] * d1 + c[12] * d2
            w[:3] += F
            w[3:] += cross(np.array(c[5]) - r, F)
        return w


def _sensor_force(friction: PulleyFriction, f, theta, thetadot, beta) -> np.ndarray:
    return friction.sensor_force(f, theta, thetadot, beta)


# the simulator's laws (docs/kernels.md): its period and measurement, and the pulley friction seen by the sensors
sim_period = kernels.law("sim_period", Simulator._step_readable, Simulator._step_fused)
sim_measure = kernels.law("sim_measure", Simulator._measure_readable, Simulator._measure_fused)
friction_sensor_force = kernels.law("friction_sensor_force", _sensor_force, kernels.friction_sensor_force)

"""The control loop of Fig. 3.4 closed around the simulator in one Python process, without ROS.

The same stage objects as the nodes (:class:`cdpr_control.control.loop.ControlLoop`) against the
same simulator as the ``winch_platform_sim`` node, one control period per step: for the closed-loop
tests, benchmarks and offline studies, where the transport between the nodes is not the subject.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from cdpr_control.control.loop import ControlLoop, ControlLoopParams
from cdpr_control.control.params import control_loop_params
from cdpr_control.motion.interpolation import Interpolator
from cdpr_control.model.kinematics import twist_from_pose_rates

from cdpr_sim.simulator import SimConfig, Simulator
from cdpr_sim.startup import calibration_forces, startup_state


@dataclass
class ClosedLoopRun:
    """Time series of a run, one row per control period."""

    t: np.ndarray          # (N,) s
    x_d: np.ndarray        # (N, 6) set-point
    x: np.ndarray          # (N, 6) ground-truth pose
    x_est: np.ndarray      # (N, 6) forward kinematics estimate
    f: np.ndarray          # (N, m) true cable forces at the platform
    f_d: np.ndarray        # (N, m) force set-points
    theta_d: np.ndarray    # (N, m) drive command
    status: np.ndarray     # (N,) force distribution status
    faults: list           # per period, the safety faults
    offsets: dict          # per offset stage, (N, 6) its output
    w_contact: np.ndarray | None = None   # (N, 6) true contact wrench on the platform (0 without obstacles)
    hpfc: list | None = None              # per period, the HPFCState (with hybrid force control)


def hold(x_d) -> Callable[[float], tuple]:
    """A set-point source holding the pose x_d."""
    x_d = np.asarray(x_d, dtype=float)
    zero = np.zeros(6)
    return lambda t: (x_d, zero, zero)


def program(interpolator: Interpolator) -> Callable[[float], tuple]:
    """A set-point source stepping a G-code interpolator once per period (twists from Kardan rates);
    it also hands on the force axes F_d,0 and the program's parameter commands (M103 ...), which
    :func:`run` applies to the loop."""
    def source(t):
        sp = interpolator.step()
        xdot, xddot = twist_from_pose_rates(sp.x, sp.xd, sp.xdd)
        return sp.x, xdot, xddot, sp.force, sp.commands
    return source


def run(robot, setpoints: Callable[[float], tuple], duration: float, params: ControlLoopParams | None = None,
        x0=None, tension_level: float = 0.0, payload: float = 0.0, payload_com=(0.0, 0.0, 0.0),
        config: SimConfig = SimConfig(), before_step: Callable | None = None,
        offset_stages: dict | None = None) -> ClosedLoopRun:
    """Simulate ``duration`` seconds: the platform starts at rest at x0 (default home) under the QP
    forces of ``tension_level`` with the encoders calibrated at home (section 2.3.2); a payload is
    attached at t = 0 (the controller does not know it); the loop gets the home calibration's
    forces for its Δq_0 (3.9), (3.23). ``before_step(k, loop, sim)`` may change
    parameters during the run. params None: the robot's parameter file (the node graph's
    configuration, :func:`cdpr_control.control.params.control_loop_params`). The simulated
    robot is the plant of ``config`` (by default one that differs from the robot file).
    ``setpoints(t)`` returns (x_d, xdot_d, xddot_d), optionally followed by the desired force F_d,0
    (3,) and a list of parameter commands; a set-point source with a ``bind(loop)`` method (one that
    closes the loop through a measurement, e.g. :class:`HandGuiding` below) gets the loop first,
    and one with a ``w_user`` attribute hands the loop the user's wrench of its set-point each period;
    ``offset_stages`` are further offset inputs of the joint command (see
    :class:`cdpr_control.control.loop.ControlLoop`)."""
    x0 = robot.home if x0 is None else np.asarray(x0, dtype=float)
    x0, theta0, offset = startup_state(robot, x0, tension_level, calibrate_home=True, config=config)
    loop = ControlLoop(robot, config.period, control_loop_params(robot) if params is None else params,
                       offset_stages)
    if hasattr(setpoints, "bind"):
        setpoints.bind(loop)
    n = int(round(duration / config.period))
    rows = {k: [] for k in ("t", "x_d", "x", "x_est", "f", "f_d", "theta_d", "status", "w_contact")}
    faults, hpfc = [], []
    offsets = {name: [] for name in loop.offset_stages}
    with Simulator(robot, config, x0=x0, theta0=theta0, encoder_offset=offset) as sim:
        loop.set_home_calibration(calibration_forces(sim, tension_level))     # Δq_0 of the encoders' set-up
        if payload:
            sim.set_payload(payload, payload_com)
        out = sim.output
        for k in range(n):
            if before_step is not None:
                before_step(k, loop, sim)
            x_d, xdot_d, xddot_d, *rest = setpoints(out.t)
            for command in rest[1] if len(rest) > 1 else ():
                loop.set_parameter(command.node, command.parameter, command.value)
            state = loop.step(out.t, x_d, xdot_d, xddot_d, out.theta, out.thetadot, out.F_s,
                              rest[0] if rest else None, getattr(setpoints, "w_user", None))
            out = sim.step(state.theta_d)
            for key, value in (("t", out.t), ("x_d", x_d), ("x", out.x), ("x_est", state.x), ("f", out.f),
                               ("f_d", state.f_d), ("theta_d", state.theta_d), ("status", state.status),
                               ("w_contact", out.w_contact)):
                rows[key].append(value)
            faults.append(state.faults)
            hpfc.append(state.hpfc)
            for name, value in state.offsets.items():
                offsets[name].append(value)
    return ClosedLoopRun(**{k: np.array(v) for k, v in rows.items()}, faults=faults,
                         offsets={name: np.array(v).reshape(-1, 6) for name, v in offsets.items()},
                         hpfc=hpfc if loop.hpfc is not None else None)


class HandGuiding:
    """A set-point source for hand guiding (section 5.2): the admittance controller's x_d,Adm.

    As in the node graph, the wrench measured in period k acts on the set-point of period k + 1.
    Starts holding ``x_hold`` (default the robot's home) with the controller enabled or not as it
    is; ``outputs`` records every period's :class:`cdpr_control.control.admittance.AdmittanceOutput`.
    ``w_user`` is the user's wrench w_Adm of the set-point last returned while the controller is the
    set-point source (else None), which :func:`run` hands to the loop's force set-point (the hand's
    reserve): the graph's force distribution node uses the admittance state of t_k in period k + 1,
    the same value.
    """

    def __init__(self, controller, x_hold=None):
        self.controller = controller
        x = np.array(controller.robot.home if x_hold is None else x_hold, dtype=float)
        self.setpoint = (x, np.zeros(6), np.zeros(6))
        self.loop: ControlLoop | None = None
        self.outputs: list = []
        self.w_user: np.ndarray | None = None

    def bind(self, loop: ControlLoop) -> None:
        self.loop = loop

    def __call__(self, t):
        state = None if self.loop is None else self.loop.state
        if state is not None:
            out = self.controller.step(state.w, *self.setpoint)
            self.setpoint = (out.x, *out.twist())
            self.outputs.append(out)
            self.w_user = out.w_user if out.active else None
        return tuple(v.copy() for v in self.setpoint)

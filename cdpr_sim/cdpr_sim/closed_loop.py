"""The control loop of Fig. 3.4 closed around the simulator in one Python process, without ROS.

The same stage objects as the nodes (:class:`cdpr_control.control_loop.ControlLoop`) against the
same simulator as the ``winch_platform_sim`` node, one control period per step: for the closed-loop
tests, benchmarks and offline studies, where the transport between the nodes is not the subject.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from cdpr_control.control_loop import ControlLoop, ControlLoopParams
from cdpr_control.interpolation import Interpolator
from cdpr_control.kinematics import twist_from_pose_rates

from .simulator import SimConfig, Simulator
from .startup import startup_state


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


def hold(x_d) -> Callable[[float], tuple]:
    """A set-point source holding the pose x_d."""
    x_d = np.asarray(x_d, dtype=float)
    zero = np.zeros(6)
    return lambda t: (x_d, zero, zero)


def program(interpolator: Interpolator) -> Callable[[float], tuple]:
    """A set-point source stepping a G-code interpolator once per period (twists from Kardan rates)."""
    def source(t):
        sp = interpolator.step()
        xdot, xddot = twist_from_pose_rates(sp.x, sp.xd, sp.xdd)
        return sp.x, xdot, xddot
    return source


def run(robot, setpoints: Callable[[float], tuple], duration: float, params: ControlLoopParams | None = None,
        x0=None, tension_level: float = 0.0, payload: float = 0.0, payload_com=(0.0, 0.0, 0.0),
        config: SimConfig = SimConfig(), before_step: Callable | None = None,
        offset_stages: dict | None = None) -> ClosedLoopRun:
    """Simulate ``duration`` seconds: the platform starts at rest at x0 (default home) under the QP
    forces of ``tension_level`` with the encoders calibrated at home (section 2.3.2); a payload is
    attached at t = 0 (the controller does not know it). ``before_step(k, loop, sim)`` may change
    parameters during the run; ``offset_stages`` are further offset inputs of the joint command
    (see :class:`cdpr_control.control_loop.ControlLoop`)."""
    x0 = robot.home if x0 is None else np.asarray(x0, dtype=float)
    x0, theta0, offset = startup_state(robot, x0, tension_level, calibrate_home=True)
    loop = ControlLoop(robot, config.period, params, offset_stages)
    n = int(round(duration / config.period))
    rows = {k: [] for k in ("t", "x_d", "x", "x_est", "f", "f_d", "theta_d", "status")}
    faults = []
    offsets = {name: [] for name in loop.offset_stages}
    with Simulator(robot, config, x0=x0, theta0=theta0, encoder_offset=offset) as sim:
        if payload:
            sim.set_payload(payload, payload_com)
        out = sim.output
        for k in range(n):
            if before_step is not None:
                before_step(k, loop, sim)
            x_d, xdot_d, xddot_d = setpoints(out.t)
            state = loop.step(out.t, x_d, xdot_d, xddot_d, out.theta, out.thetadot, out.F_s)
            out = sim.step(state.theta_d)
            for key, value in (("t", out.t), ("x_d", x_d), ("x", out.x), ("x_est", state.x), ("f", out.f),
                               ("f_d", state.f_d), ("theta_d", state.theta_d), ("status", state.status)):
                rows[key].append(value)
            faults.append(state.faults)
            for name, value in state.offsets.items():
                offsets[name].append(value)
    return ClosedLoopRun(**{k: np.array(v) for k, v in rows.items()}, faults=faults,
                         offsets={name: np.array(v).reshape(-1, 6) for name, v in offsets.items()})

"""Energy use of a planned trajectory or a recorded run, thesis section 4.4 (Fig. 4.31-4.35).

The model is :mod:`cdpr_control.model.energy` ((4.9)-(4.14), table 4.6). Its inputs per sample are the
forces at the platform f, the cable velocities thetadot and accelerations thetaddot and the wrap
angles of the swivelling pulleys:

* a planned trajectory (:func:`trajectory_power`): a G-code program interpolated jerk-limited
  (:class:`cdpr_control.motion.interpolation.Interpolator`), the wrench of the motion (2.33) with the
  payload, the QP forces (3.27) at a tension level and the cable velocities and accelerations of
  the rigid kinematics (2.12)-(2.13): the elongation rate of the cables is left out (it changes
  only the elastic energy stored in them, and the QP's active-set switches would turn it into
  spikes of thetaddot);
* a recorded run (:func:`run_power`): measured theta, forces and poses (the bag reading is in
  cdpr_tools, ``cdpr analyze energy BAG``), derivatives by a Savitzky-Golay filter (encoder
  quantisation would otherwise dominate the winch inertia term).

The reference trip of Fig. 4.34 (:data:`REFERENCE_TRIP`): 100 kg lifted by 1.0 m, moved 2.4 m and
lowered by 1.0 m at 1.5 m/s, 5 m/s^2, 20 m/s^3, QP at minimal forces; the thesis reports 4.12 Wh
and a peak of about 8 kW (section 4.4.3). The thesis does not give the start point; the program
(programs/reference_trip_ipanema3.gcode) moves relatively from where it starts.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdpr_control.model.dynamics import platform_wrench
from cdpr_control.model.energy import PowerFlow, power_flow
from cdpr_control.force_distribution import quadratic_program
from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.interpolation import AxisLimits, Interpolator, Limits, ProgramState
from cdpr_control.model.kinematics import (cable_accelerations, cable_velocities, inverse_kinematics,
    twist_from_pose_rates)
from cdpr_control.programs import read as read_program

LEVELS = {"minimal": 0.0, "medium": 0.5, "maximal": 1.0}     # f_ref of (3.27), section 4.4.3


@dataclass(frozen=True)
class TripSpec:
    """A planned task: program, start pose, payload and path limits."""

    program: str                  # shipped name or G-code text
    start: tuple                  # (6,) pose x [m, rad]
    payload: float                # kg, point mass at the platform origin
    velocity: float               # m/s
    acceleration: float           # m/s^2
    jerk: float                   # m/s^3


# Fig. 4.34: start point and direction ASSUMPTION (the thesis shows them only in a picture): the
# lift starts at the height of the workspace centre, the 2.4 m move along y is centred on it.
REFERENCE_TRIP = TripSpec("reference_trip_ipanema3", (0.0, -1.2, 0.5, 0.0, 0.0, 0.0), 100.0, 1.5, 5.0, 20.0)
THESIS_REFERENCE_TRIP = {"energy_Wh": 4.12, "peak_power_W": 8000.0}     # section 4.4.3


@dataclass
class Motion:
    """Set-points at the samples t (N,): poses x, twists xdot and their derivatives xddot (N, 6)."""

    t: np.ndarray
    x: np.ndarray
    xdot: np.ndarray
    xddot: np.ndarray


def program_motion(program: str, start, velocity: float, acceleration: float, jerk: float,
                   dt: float = 1e-3) -> Motion:
    """The jerk-limited set-points of a G-code program (shipped name or text) from the pose start."""
    text = read_program(program) if "\n" not in program else program
    limits = Limits(translation=AxisLimits(velocity, acceleration, jerk))
    interp = Interpolator(parse_gcode(text, start_pose=np.asarray(start, dtype=float)), limits, dt)
    rows = []
    while interp.state is not ProgramState.DONE:
        sp = interp.step()
        if interp.state not in (ProgramState.RUNNING, ProgramState.DONE):
            raise ValueError(f"program stopped in state {interp.state.value}: stops and parameter "
                             "commands are not evaluated")
        xdot, xddot = twist_from_pose_rates(sp.x, sp.xd, sp.xdd)
        rows.append((sp.t, sp.x, xdot, xddot))
    t, x, xdot, xddot = (np.array(c) for c in zip(*rows))
    return Motion(t, x, xdot, xddot)


def hold_motion(x, duration: float, dt: float = 1e-3) -> Motion:
    """Standstill at pose x for duration s."""
    n = int(round(duration / dt)) + 1
    x = np.repeat(np.asarray(x, dtype=float)[None], n, axis=0)
    return Motion(np.arange(n) * dt, x, np.zeros_like(x), np.zeros_like(x))


@dataclass
class TrajectoryEnergy:
    """A planned motion evaluated at one tension level."""

    level: float
    flow: PowerFlow
    f: np.ndarray                 # (N, m) N, QP forces at the platform
    feasible: np.ndarray          # (N,) bool, the QP found forces within f_min .. f_max


def trajectory_power(robot, motion: Motion, level: float = 0.0, payload: float = 0.0) -> TrajectoryEnergy:
    """(4.9)-(4.14) along a planned motion with QP forces (3.27) at the tension level [0..1]."""
    loaded = robot.with_payload(payload) if payload else robot
    ik = inverse_kinematics(loaded, motion.x)
    w = platform_wrench(loaded, motion.x, motion.xdot, motion.xddot)          # (2.33)
    c = robot.cable
    result = quadratic_program(ik.AT, w, c.f_min, c.f_max, c.f_min + level * (c.f_max - c.f_min))
    f = np.asarray(result.f)
    thetadot = cable_velocities(ik, motion.xdot)                              # (2.12)
    thetaddot = cable_accelerations(ik, motion.xdot, motion.xddot)            # (2.13)
    flow = power_flow(robot, motion.t, f, thetadot, thetaddot, ik.beta)
    return TrajectoryEnergy(level, flow, f, np.asarray(result.feasible))


def run_power(robot, t, theta, f, x, window: float = 0.021) -> PowerFlow:
    """(4.9)-(4.14) for a recorded run: stamps t (N,), cable lengths theta and platform forces f
    (N, m), poses x (N, 6) (wrap angles of the swivelling pulleys by the IK).

    thetadot and thetaddot by a cubic Savitzky-Golay filter over ``window`` s of theta.
    """
    from scipy.signal import savgol_filter

    t, theta = np.asarray(t, dtype=float), np.asarray(theta, dtype=float)
    dt = float(np.median(np.diff(t)))
    n = max(int(round(window / dt)) // 2 * 2 + 1, 5)
    thetadot = savgol_filter(theta, n, 3, deriv=1, delta=dt, axis=0)
    thetaddot = savgol_filter(theta, n, 3, deriv=2, delta=dt, axis=0)
    return power_flow(robot, t, f, thetadot, thetaddot, inverse_kinematics(robot, x).beta)


def platform_work(robot, t, x, f) -> np.ndarray:
    """Power the cables deliver to the rigid platform, -sum f qdot with q = IK{x} [W] (N,).

    Independent of the winch side: it is the rate of the platform's kinetic plus potential energy
    (and the work against external wrenches); differences to -sum f thetadot are the cables'
    elastic energy and damping.
    """
    q = inverse_kinematics(robot, x).q
    return -(np.asarray(f) * np.gradient(q, t, axis=0)).sum(axis=1)


def summary(flow: PowerFlow) -> dict:
    """Energies [Wh], peak and mean electrical power [W], loss shares of one PowerFlow."""
    E = flow.energies()
    duration = float(flow.t[-1] - flow.t[0])
    return {
        "duration_s": duration,
        "E_el_Wh": E["E_el"] / 3600.0,
        "E_mech_Wh": E["E_mech"] / 3600.0,
        "E_pulley_Wh": E["E_pulley"] / 3600.0,
        "E_winch_Wh": E["E_winch"] / 3600.0,
        "E_servo_Wh": E["E_servo"] / 3600.0,
        "E_cabinet_Wh": E["E_cabinet"] / 3600.0,
        "E_rec_Wh": E["E_rec"] / 3600.0,
        "P_el_peak_W": float(flow.P_el.max()),
        "P_el_mean_W": E["E_el"] / duration if duration > 0 else float(flow.P_el[0]),
        "loss_shares": flow.loss_shares(),
    }


def plot_winch_efficiency(robot, path) -> None:
    """PNG of the winch efficiency map (4.15) over cable force and velocity (Fig. 4.32)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cdpr_control.model.energy import winch_efficiency

    v_max = robot.drive.v_max
    f = np.linspace(float(np.min(robot.cable.f_min)), float(np.max(robot.cable.f_max)), 120)
    v = np.linspace(-v_max, v_max, 161)
    eta = winch_efficiency(robot, f[:, None], v[None, :])
    fig, ax = plt.subplots(figsize=(6, 4))
    # hauling in (motor operation) on the right, as in Fig. 4.32
    im = ax.contourf(-v, f, 100 * eta, levels=np.arange(0, 101, 5), cmap="viridis")
    fig.colorbar(im, ax=ax, label="eta_w [%]")
    ax.set_xlabel("hauling-in cable velocity -thetadot [m/s] (left: generator)")
    ax.set_ylabel("cable force f_w [N]")
    ax.set_title(f"{robot.name}: winch efficiency (4.15), blank: undefined", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=72)
    plt.close(fig)


def plot(flows: dict, path, title: str = "") -> None:
    """Power over time (Fig. 4.35) and the losses per subsystem (Fig. 4.31) of labelled PowerFlows."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [2, 1]})
    for label, flow in flows.items():
        ax.plot(flow.t, 1e-3 * flow.P_el, label=f"P_el {label}")
    first = next(iter(flows.values()))
    ax.plot(first.t, 1e-3 * first.P_mech, "k--", lw=1, label="P_mech (platform)")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("power [kW]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    names = ("P_pulley", "P_winch", "P_servo", "P_cabinet")
    bottom = np.zeros(len(flows))
    for name in names:
        values = np.array([flow.energy(name) / 3600.0 for flow in flows.values()])
        bx.bar(list(flows), values, bottom=bottom, label=name[2:])
        bottom += values
    bx.set_ylabel("losses [Wh]")
    bx.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)

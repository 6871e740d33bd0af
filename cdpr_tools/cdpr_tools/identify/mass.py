"""Platform mass (and centre of gravity, cog.py) from the circle run, thesis section 4.1.1, (4.2)-(4.4).

On the circle at constant angular velocity thetadot_c the platform accelerates by
r_c thetadot_c^2 towards the centre (4.2), so the cable wrench w = A^T f (2.10) carries a first
harmonic of amplitude m_p r_c thetadot_c^2 in x and y (4.3). The forces are the sensor forces
with the pulley-friction compensation (3.44) of the control loop (robot file or identified
parameters); A^T and r_c come from the recorded pose (``ground_truth/pose``, else the set-point).
The first harmonics of w_x, w_y and of the pose x, y are fitted by linear least squares (a DFT at
the circle frequency) over the constant-velocity window, so

    m_p = |W_xy| / (thetadot_c^2 |X_xy|)                  (4.3)

The static part gives the second estimate (4.4), m_p = w_z / (xddot_z - g_z), averaged over the
window (xddot_z = 0 on a horizontal circle; g_z = -9.81 m/s^2 in the base frame, z up).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdpr_control.control.friction_compensation import FrictionCompensation, FrictionCompensationParams
from cdpr_control.model.kinematics import inverse_kinematics

from cdpr_tools.identify import bag_data, cog


@dataclass
class MassFit:
    m_circle: float              # kg, from the force harmonics (4.3)
    m_static: float              # kg, from w_z (4.4)
    frequency: float             # Hz, circle frequency found in the set-points
    r_c: float                   # m, measured circle radius
    window: tuple                # s, (start, end) of the constant-velocity window
    c_mp: np.ndarray             # m, centre of gravity in the platform frame (4.3), see cog.py
    t: np.ndarray = field(repr=False)        # s, the window's stamps
    w_xy: np.ndarray = field(repr=False)     # N, (n, 2) w_x, w_y of the cable forces there
    w_fit: np.ndarray = field(repr=False)    # N, (n, 2) their first harmonics (with the mean)


def cable_wrench(robot, x, f) -> np.ndarray:
    """w = A^T f (N, 6) at poses x (N, 6), (2.10)."""
    return np.array([inverse_kinematics(robot, xk).AT @ fk for xk, fk in zip(x, f)])


def compensated_forces(robot, data, dt: float, friction_params: dict | None = None) -> np.ndarray:
    """f (N, m) from the sensor forces through the friction compensation (3.44) of the control loop."""
    p = friction_params or {}
    stage = FrictionCompensation(robot, dt, FrictionCompensationParams(
        mu=p.get("mu"), sigma=p.get("sigma"), F_pv=p.get("F_pv")))
    return np.array([stage.update(F_s, th, thd, b) for F_s, th, thd, b in zip(data.F_s, data.theta, data.thetadot,
                                                                         data.beta)])


def _harmonic(t, y, omega) -> complex:
    """Complex amplitude of the first harmonic of y (N,) at omega (least squares with a constant)."""
    return _harmonic_fit(t, y, omega)[0]


def _harmonic_fit(t, y, omega) -> tuple[complex, np.ndarray]:
    """(complex amplitude of the first harmonic of y at omega, the fitted harmonic plus constant)."""
    M = np.column_stack([np.cos(omega * t), np.sin(omega * t), np.ones_like(t)])
    coefficients = np.linalg.lstsq(M, y, rcond=None)[0]
    return complex(coefficients[0], -coefficients[1]), M @ coefficients


def constant_speed_window(t, x_d, tolerance: float = 0.01):
    """Mask of the samples whose set-point speed is within ``tolerance`` of the circle's, cut to whole turns;
    with the circle's frequency [Hz] and the set-point radius [m].

    The circle's speed is the most frequent one (a histogram of log v in bins of ``tolerance``), and
    the window the longest stretch at it: a program reaches the circle by a faster rapid move (G0)
    and leaves it again, so the fastest samples are not the circle's."""
    v = np.linalg.norm(np.gradient(x_d[:, :2], t, axis=0), axis=1)
    moving = v > 1e-3 * max(float(v.max()), 1e-12)
    if not moving.any():
        raise ValueError("the set-points do not move: no circle in the run")
    log_v = np.log(v[moving])
    counts, edges = np.histogram(log_v, bins=max(int(np.ptp(log_v) / tolerance), 1))
    k = int(np.argmax(counts))
    v_c = float(np.exp(np.median(log_v[(log_v >= edges[k]) & (log_v <= edges[k + 1])])))
    idx = _longest_run(np.abs(v / v_c - 1.0) < tolerance)
    xy = x_d[idx, :2]
    centre = 0.5 * (xy.max(axis=0) + xy.min(axis=0))
    radius = float(np.mean(np.linalg.norm(xy - centre, axis=1)))
    frequency = float(np.median(v[idx]) / (2.0 * np.pi * radius))
    turns = np.floor((t[idx[-1]] - t[idx[0]]) * frequency)
    if turns < 1:
        raise ValueError("the run has less than one turn at constant speed")
    return (t >= t[idx[0]]) & (t <= t[idx[0]] + turns / frequency), frequency, radius


def _longest_run(mask) -> np.ndarray:
    """Indexes of the longest stretch of consecutive True samples of ``mask`` (not all False)."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    k = int(np.argmax(ends - starts))
    return np.arange(starts[k], ends[k])


def identify(bag, robot, friction_params: dict | None = None, use_reference: bool = False) -> MassFit:
    """Mass of the platform from the circle run in ``bag``; use_reference: ground-truth forces instead."""
    from cdpr_tools.identify.friction import load_data

    data = load_data(bag, robot)
    dt = float(np.median(np.diff(data.t)))
    x = bag_data.poses(bag, data.t)
    x_d = _setpoints(bag, data.t)
    f = data.f_ref if use_reference else compensated_forces(robot, data, dt, friction_params)
    w = cable_wrench(robot, x, f)
    mask, frequency, _ = constant_speed_window(data.t, x_d)
    t = data.t[mask]
    omega = 2.0 * np.pi * frequency
    fits = [_harmonic_fit(t, w[mask, j], omega) for j in (0, 1)]
    W = np.array([amplitude for amplitude, _ in fits])
    X = np.array([_harmonic(t, x[mask, j], omega) for j in (0, 1)])
    m_circle = float(np.linalg.norm(W) / (omega**2 * np.linalg.norm(X)))
    m_static = float(np.mean(w[mask, 2]) / (0.0 - robot.gravity[2]))
    xddot = cog.accelerations(data.t, x)[mask]
    c_mp = cog.centre_of_gravity(t, x[mask], xddot, w[mask, 3:], m_circle, omega, robot.gravity)
    return MassFit(m_circle, m_static, frequency, float(np.linalg.norm(X) / np.sqrt(2.0)), (t[0], t[-1]), c_mp,
                   t, w[mask, :2], np.column_stack([fitted for _, fitted in fits]))


def plot(fit: MassFit, path, title: str = "") -> None:
    """PNG (1000 x 450 px): w_x, w_y of the cable forces over the constant-speed window and their
    fitted first harmonics, whose amplitude is m_p r_c thetadot_c^2 (4.3). ``title``: robot,
    controller and bag (:func:`cdpr_tools.identify.bag_data.run_title`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 4.5))
    for j, (name, colour) in enumerate((("w_x", "tab:blue"), ("w_y", "tab:orange"))):
        ax.plot(fit.t, fit.w_xy[:, j], lw=1.6, color=colour, alpha=0.45, label=f"{name} = (A^T f)_{name[-1]}")
        ax.plot(fit.t, fit.w_fit[:, j], lw=0.9, ls="--", color=colour, label=f"{name}: first harmonic + mean")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("cable wrench force [N]")
    ax.legend(fontsize=8, ncol=2, loc="upper right")
    ax.set_title(f"Mass from the circle (4.3): m_p {fit.m_circle:.4f} kg (harmonics), {fit.m_static:.4f} kg (w_z, (4.4)); "
                 f"r_c {1e3 * fit.r_c:.1f} mm at {fit.frequency:.3f} Hz" + (f"\n{title}" if title else ""), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _setpoints(bag, t) -> np.ndarray:
    """x_d (N, 6) held from the set-points onto stamps t (needs the ``setpoint`` topic)."""
    from cdpr_control.ros.conversions import quaternion_to_kardan

    fields = [f"pose.position.{a}" for a in "xyz"] + [f"pose.orientation.{a}" for a in "xyzw"]
    t_p, *cols = bag.series(bag_data.TOPIC_SETPOINT, *fields, stamp="header")
    idx = np.clip(np.searchsorted(t_p, t + 1e-12, side="right") - 1, 0, None)
    x = np.empty((len(t), 6))
    x[:, :3] = np.column_stack(cols[:3])[idx]
    x[:, 3:] = np.array([quaternion_to_kardan(*q) for q in zip(*cols[3:])])[idx]
    return x

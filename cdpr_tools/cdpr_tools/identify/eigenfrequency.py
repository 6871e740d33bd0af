"""Eigenfrequency of the platform from its free oscillation, thesis section 4.3, (4.8).

The drives hold, a knock excites the platform (``experiments.record_pulse_response``); the recorded
z of the pose (``ground_truth/pose``: the laser tracker; else the set-point, useless here) decays as
a damped oscillation. From the first extreme after the knock until the amplitude has fallen to
``decay`` of it, least squares fits

    z(t) = z_0 + A exp(-zeta omega_n t) cos(omega_d t + phi),   omega_d = omega_n sqrt(1 - zeta^2)

(started from the zero-crossing rate), giving the damped frequency f_d and the undamped f_n that
(4.8) predicts: f_n = sqrt(K_x,zz / m_p) / (2 pi), K_x = K_g + K_c (2.22) at the resting pose with the
cable stiffness (2.20) at the resting forces (sensor forces through the friction compensation, or the
reference forces), m_p from the robot file (dynamics.mass_matrix). The coupled modes
(stiffness.modal_frequencies) are given too: the z mode is the one nearest to f_n.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from cdpr_control.model import cable
from cdpr_control.model.dynamics import mass_matrix
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.stiffness import eigenfrequencies, modal_frequencies, operational_stiffness

from cdpr_tools.identify import bag_data


@dataclass
class EigenFit:
    f_d: float                   # Hz, damped frequency of the z oscillation
    zeta: float                  # damping ratio
    f_n: float                   # Hz, undamped f_d / sqrt(1 - zeta^2): what (4.8) predicts
    f_model: float               # Hz, (4.8) with K_x,zz at the resting forces and m_p of the robot file
    f_modes: np.ndarray          # Hz, coupled undamped modes of the model, ascending
    amplitude: float             # m, z amplitude at the start of the fit
    window: tuple                # s, (start, end) of the fitted decay
    rms: float                   # m, residual of the fit
    t: np.ndarray                # s, stamps of the fitted samples
    z: np.ndarray                # m, measured z there
    z_fit: np.ndarray            # m, fitted z there


def damped_oscillation(t, p) -> np.ndarray:
    """z_0 + A exp(-sigma t) cos(omega_d t + phi) for p = (z_0, A, sigma, omega_d, phi)."""
    z0, A, sigma, omega_d, phi = p
    return z0 + A * np.exp(-sigma * t) * np.cos(omega_d * t + phi)


def decay_window(z, rest: int, decay: float = 0.02):
    """(first, last) sample of the decay: from the largest deviation from the rest level (median of
    the first ``rest`` samples) to the last sample still above ``decay`` times it."""
    dz = np.abs(z - np.median(z[:rest]))
    first = int(np.argmax(dz))
    last = first + int(np.flatnonzero(dz[first:] > decay * dz[first])[-1])
    if last - first < 8:
        raise ValueError("no oscillation found in the pose (the knock is missing or too small)")
    return first, last + 1


def fit_decay(t, z) -> np.ndarray:
    """Least-squares p = (z_0, A, sigma, omega_d, phi) of :func:`damped_oscillation` on (t, z), t from 0."""
    z0 = z[-1]
    crossings = np.flatnonzero(np.diff(np.sign(z - z0)) != 0)
    omega = np.pi / np.mean(np.diff(t[crossings])) if len(crossings) > 1 else np.pi / (t[-1] - t[0])
    A = z[0] - z0
    sigma = np.log(50.0) / t[-1]          # the window ends at ~2 % of the first extreme
    p0 = (z0, A, sigma, omega, 0.0)
    scale = np.abs(A) + 1e-12
    return least_squares(lambda p: (damped_oscillation(t, p) - z) / scale, p0, x_scale="jac").x


def model_frequencies(robot, x, f):
    """((4.8) z eigenfrequency, coupled modes) [Hz] at pose x with cable forces f (2.20), (2.22)."""
    ik = inverse_kinematics(robot, x)
    k_l = cable.tangent_stiffness(robot, f, cable.total_free_length(robot, ik.q))
    K_x = operational_stiffness(ik, f, k_l)
    M = mass_matrix(robot, x)
    return float(eigenfrequencies(K_x, M)[2]), modal_frequencies(K_x, M)


def identify(bag, robot, friction_params: dict | None = None, use_reference: bool = False,
             rest: float = 0.1) -> EigenFit:
    """Eigenfrequency of the z oscillation in ``bag``; the first ``rest`` s are the resting state."""
    from cdpr_tools.identify.friction import load_data
    from cdpr_tools.identify.mass import compensated_forces

    data = load_data(bag, robot)
    x = bag_data.poses(bag, data.t)
    dt = float(np.median(np.diff(data.t)))
    n_rest = max(int(round(rest / dt)), 1)
    first, last = decay_window(x[:, 2], n_rest)
    t = data.t[first:last] - data.t[first]
    z = x[first:last, 2]
    z0, A, sigma, omega_d, phi = fit_decay(t, z)
    omega_n = np.hypot(omega_d, sigma)                  # sigma = zeta omega_n, omega_d = omega_n sqrt(1 - zeta^2)
    f = data.f_ref if use_reference else compensated_forces(robot, data, dt, friction_params)
    f_model, modes = model_frequencies(robot, np.mean(x[:n_rest], axis=0), np.mean(f[:n_rest], axis=0))
    z_fit = damped_oscillation(t, (z0, A, sigma, omega_d, phi))
    return EigenFit(f_d=float(omega_d / (2 * np.pi)), zeta=float(sigma / omega_n), f_n=float(omega_n / (2 * np.pi)),
                    f_model=f_model, f_modes=modes, amplitude=float(abs(A)),
                    window=(float(data.t[first]), float(data.t[last - 1])),
                    rms=float(np.sqrt(np.mean((z_fit - z) ** 2))), t=t + data.t[first], z=z, z_fit=z_fit)


def plot(fit: EigenFit, path, title: str = "") -> None:
    """The measured z decay and the fitted damped oscillation (800 x 400 px); ``title``: robot,
    controller and bag (:func:`cdpr_tools.identify.bag_data.run_title`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(fit.t, 1e3 * fit.z, ".", ms=3, label="z measured (tracker)")
    ax.plot(fit.t, 1e3 * fit.z_fit, "-", label=f"fit: f_d {fit.f_d:.2f} Hz, zeta {fit.zeta:.3f}")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("z [mm]")
    ax.set_title(f"Eigenfrequency in z: f_n {fit.f_n:.2f} Hz measured, {fit.f_model:.2f} Hz model (4.8)"
                 + (f"\n{title}" if title else ""), fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)

"""Cable stiffness k0, k1, k2 of (2.16) from force/elongation data at rest.

At rest the elongation of cable i is dq = IK{x} - theta (2.24) up to the encoder's calibration
offset delta_i (section 2.3.2: the encoders read IK{home} under the start-up tension), and (2.17)
gives dq = f l_t / (k0 + k1 f + k2 f^2) with l_t = q + l_0 (2.14). Least squares over k0, k1, k2
(one cable type for the robot) and delta_i per cable on the samples where the command has stood
still for ``settle`` s (the platform has come to rest). f: the sensor forces through the loop's
friction compensation (3.44), or the reference forces.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from cdpr_control import cable
from cdpr_control.kinematics import inverse_kinematics

from . import bag_data


@dataclass
class StiffnessFit:
    k0: float                    # N
    k1: float                    # -
    k2: float                    # 1/N
    delta: np.ndarray            # (m,) m, encoder offsets
    rms: float                   # m, elongation residual
    n_samples: int


def resting_mask(t, t_c, theta_d, settle: float) -> np.ndarray:
    """Samples at stamps t whose command has not changed for at least ``settle`` s."""
    moved = np.concatenate([[True], np.any(np.diff(theta_d, axis=0) != 0.0, axis=1)])
    last_change = np.maximum.accumulate(np.where(moved, t_c, -np.inf))
    idx = np.clip(np.searchsorted(t_c, t, side="right") - 1, 0, None)
    return t - last_change[idx] >= settle


def identify(bag, robot, friction_params: dict | None = None, use_reference: bool = False,
             settle: float = 0.2, start=(20000.0, 0.0, 0.0)) -> StiffnessFit:
    from .friction import load_data
    from .mass import compensated_forces

    data = load_data(bag, robot)
    t_c, theta_d = bag_data.commands(bag)
    mask = resting_mask(data.t, t_c, theta_d, settle)
    if mask.sum() < 10:
        raise ValueError("no samples at rest: hold the command still for longer than settle")
    dt = float(np.median(np.diff(data.t)))
    f = (data.f_ref if use_reference else compensated_forces(robot, data, dt, friction_params))[mask]
    x = bag_data.poses(bag, data.t)[mask]
    q = np.array([inverse_kinematics(robot, xk).q for xk in x])
    dq_enc = q - data.theta[mask]                     # elongation without the encoder offset
    l_t = cable.total_free_length(robot, q)
    m = robot.m
    scale = np.array([start[0], 100.0, 1.0])

    def model(p):
        k0, k1, k2 = p[:3] * scale
        r = dataclasses.replace(robot, cable=dataclasses.replace(robot.cable, k0=k0, k1=k1, k2=k2))
        return cable.elongation_from_force(r, f, l_t)

    def residual(p):
        return (model(p) - dq_enc - p[3:] * 1e-3).ravel()

    p0 = np.concatenate([np.array(start) / scale, np.zeros(m)])
    res = least_squares(residual, p0, method="lm", xtol=1e-12, ftol=1e-12)
    k0, k1, k2 = res.x[:3] * scale
    return StiffnessFit(float(k0), float(k1), float(k2), res.x[3:] * 1e-3,
                        float(np.sqrt(np.mean(res.fun**2))), int(mask.sum()))

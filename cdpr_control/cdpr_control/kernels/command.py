"""Compiled period of the joint command (5.10): θ_d = IK{x_d + x_offset} - Δq_CFC, rate-limited.

:meth:`cdpr_control.joint_command.JointCommand.update` with one offset sum, as one call instead of
the offset pose, :func:`.model.joint_command_step` and three numpy operations on 8 numbers (call
overhead at 1 kHz): the same operations in the same order (x_d + offset, the step of
:func:`.model.joint_command_kernel`, θ̇_d = Δθ / dt, θ_d + Δθ), so the same numbers, bit for bit
(tests/test_control_fast_paths.py).
"""
from __future__ import annotations

import numba
import numpy as np

from .model import joint_command_kernel


@numba.njit(cache=True, error_model="numpy")
def joint_command_period(x_d, offset, a, b, R_A, r_p, pulleys, dq_cfc, theta_d, step, dt, theta_next, velocity):
    """θ_d of the next period into theta_next (m,) and θ̇_d into velocity (m,): the target
    q(x_d + offset) - Δq_CFC ((2.7), (5.10)) approached by at most ±step; False (outputs not set)
    when the target is not finite."""
    x = np.empty(6)
    for k in range(6):
        x[k] = x_d[k] + offset[k]
    delta = np.empty(theta_d.shape[0])
    if not joint_command_kernel(x, a, b, R_A, r_p, pulleys, dq_cfc, theta_d, step, delta):
        return False
    for i in range(delta.shape[0]):
        velocity[i] = delta[i] / dt
        theta_next[i] = theta_d[i] + delta[i]
    return True

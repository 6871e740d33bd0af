"""The simulator's control period in two compiled calls: the numbers of Simulator's readable path.

:meth:`cdpr_sim.simulator.Simulator.step` runs, per physics step, the drives (3.10)/(5.11), the
linearly implicit cable wrench (:meth:`cdpr_sim.cables.CableModel.implicit_wrench`) and, per
control period, the measurement: the cable forces (2.16)-(2.17), (2.24), the Kardan angles of the
pose (2.1), the settlement (section 4.1.3), the encoders (2.25), the pulley friction to the force
sensor (3.30)-(3.44), (3.36) and the AD converter (3.29). Written as numpy expressions and method
calls on 3-, 6- and m-vectors, the period cost some 40 calls whose overhead (about a microsecond
each) was most of the simulator's time; here the arithmetic after the pybullet calls is
:func:`substep` and :func:`measure`, two calls.

Why the numbers are the same: both run the same compiled functions as the readable path
(``drive_step``, ``implicit_wrench_kernel``, ``cable_wrench_kernel``, ``settle_kernel``, ``winch_readings_kernel``,
``sensor_force_kernel``, ``quantise_kernel``) on the same arguments, and the glue between them is element
copies and the element-wise expressions of the numpy code (u = theta_d - offset, theta + s,
theta_u + l_0, F + w, f (1 - cos beta_1)), the same operation on each element. numba's fastmath
stays off, so no operation is reordered or contracted. tests/sim/test_sim_fused_period.py compares the
two paths bit for bit.

Compiled with the project's :func:`cdpr_control.kernels.jit.njit`: its disk cache is renewed when any
compiled source changes, a callee in another file included.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from cdpr_control.kernels.jit import njit

from cdpr_sim.drive_models import drive_step
from cdpr_control.kernels.friction import sensor_force_kernel

from cdpr_sim.cables import cable_wrench_kernel, implicit_wrench_kernel
from cdpr_sim.plant import settle_kernel
from cdpr_sim.sensors import quantise_kernel, encoder_count


@functools.cache
def compiled(fn):
    """numba-compiled (and disk-cached) version of a numpy kernel, one per function and process."""
    return njit(fn)


_drive_step = compiled(drive_step)        # the drives' own compiled step (DriveModel(jit=compiled))


@njit
def winch_readings_kernel(theta, theta_prev, encoder_offset, resolution, theta_enc_prev, rate):
    """The winch side of Simulator._measure in one pass over the cables (once per control period;
    as numpy expressions on m values they cost several times more): the period's mean velocity
    (theta - theta_prev) rate, the drive position in encoder coordinates theta_true = theta +
    encoder_offset, the encoder reading of it (Encoder.read) and that reading's difference quotient."""
    m = theta.shape[0]
    thetadot, theta_true, theta_enc, thetadot_enc = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    for i in range(m):
        thetadot[i] = (theta[i] - theta_prev[i]) * rate
        theta_true[i] = theta[i] + encoder_offset[i]
        theta_enc[i] = encoder_count(theta_true[i], resolution)
        thetadot_enc[i] = (theta_enc[i] - theta_enc_prev[i]) * rate
    return thetadot, theta_true, theta_enc, thetadot_enc


@njit
def kardan_into(R, x):
    """x[3:6] = platform.kardan_angles(R): [a, b, c] with R = Rx(a) Ry(b) Rz(c) (section 2.1.1), the
    same libm functions on the same numbers."""
    x[3] = math.atan2(-R[1, 2], R[2, 2])
    x[4] = math.asin(max(-1.0, min(1.0, R[0, 2])))
    x[5] = math.atan2(-R[0, 1], R[0, 0])


@njit
def substep(theta_d, offset, u, Phi, G_new, G_old, x, buffer, head, delay, v_max, dt, thetadot, thetadot_0,
            f, A, d, h, mass, c_p, J_p, R, g, w_load, w, external, FT, theta):
    """One physics step's forces: the drive command u = theta_d - offset (encoder to drive
    coordinates), the drives' step (drive_models.drive_step, (3.10)/(5.11)) from thetadot_0 (a copy
    of the velocity before it) to thetadot, and the implicit cable wrench of the step
    (cables.implicit_wrench_kernel) plus the external wrench w when ``external``, into FT (6,).

    Writes the drives' position after the step into theta (m,) (a new array from the caller, see
    :func:`measure`); returns (the drives' next ring-buffer head, cables that went slack), head -1
    when u is not finite, before anything is changed.
    """
    m = u.shape[0]
    finite = True
    for i in range(m):
        u[i] = theta_d[i] - offset[i]
        finite = finite and math.isfinite(u[i])
    if not finite:
        return -1, 0
    for i in range(m):
        thetadot_0[i] = thetadot[i]
    head = _drive_step(u, Phi, G_new, G_old, x, buffer, head, delay, v_max, dt, thetadot)
    dropped = implicit_wrench_kernel(A, f, d, thetadot_0, thetadot, h, mass, c_p, J_p, R, g, w_load, FT)
    if external:
        for k in range(6):
            FT[k] += w[k]
    theta[:] = x[0]
    return head, dropped


@njit
def measure(pos, rot, lin, ang, theta, s, thetadot_drive, refresh_distance,
            b, c, wrap, l_0_plant, e_grid, f_grid, k_grid, tau, h, ref, f_buf, FT, anchors, A_buf, d_buf, hint,
            l_0, settle_ratio, f_settled, k0, settle_alpha, A_next, d_next,
            theta_prev, offset, resolution, theta_enc_prev, rate,
            friction, alpha_t, gamma_t, sigma, v_eps, dahl, tol, max_iterations, sensor_gain, gain,
            noise, noisy, k1, k0_ad, code_min, code_max, r1, r0,
            r, R, x, xdot, f, theta_true, theta_enc, thetadot_enc, F_s_true, F_s):
    """Simulator._measure after the pybullet reads, for a platform origin at pos (3,) with rotation
    rot (9,) (row-major) and twist lin, ang (3,): the cable forces (cables.cable_wrench_kernel) at the
    unstretched lengths theta + s, the pose x = [r, Kardan angles (2.1)], the settlement step,
    copies of the linearisation into A_next, d_next, the winch readings and the sensor forces
    (friction, sensor_force_kernel, or the sensor pulley's gain (3.36)) read through the AD
    converter (quantise_kernel with the noise row when ``noisy``).

    Writes the platform origin r (3,) and rotation R (3, 3), the pose x (6,), the twist xdot (6,),
    the forces f (m,), the winch readings theta_true, theta_enc, thetadot_enc (m,) and the sensor
    forces F_s_true, F_s (m,): new arrays from the caller (numba's boxing of a returned array costs
    more than numpy making an empty one). Returns (status, overload, moved); status 1: the anchors
    moved more than refresh_distance (refresh_distance < 0: no check) and only r, R, x and the
    cable model's buffers are written: refresh the pulley IK and call again.
    """
    m = theta.shape[0]
    v = np.empty(3)
    omega = np.empty(3)
    for k in range(3):
        r[k], v[k], omega[k] = pos[k], lin[k], ang[k]
        for j in range(3):
            R[k, j] = rot[3 * k + j]
    theta_u = np.empty(m)
    for i in range(m):
        theta_u[i] = theta[i] + s[i]                  # unstretched length incl. settlement
    overload, moved = cable_wrench_kernel(b, c, wrap, l_0_plant, e_grid, f_grid, k_grid, tau, h, r, R, v, omega, theta_u,
                                    thetadot_drive, ref, f_buf, FT, anchors, A_buf, d_buf, hint)
    for k in range(3):
        x[k], xdot[k], xdot[3 + k] = r[k], v[k], omega[k]
    kardan_into(R, x)
    if refresh_distance >= 0.0 and moved > refresh_distance:
        return 1, overload, moved
    f[:] = f_buf
    if settle_ratio != 0.0:                           # acts from the next step
        l_t = np.empty(m)
        for i in range(m):
            l_t[i] = theta_u[i] + l_0[i]
        settle_kernel(s, f, l_t, f_settled, settle_ratio, k0, settle_alpha)
    A_next[:, :] = A_buf
    d_next[:] = d_buf
    thetadot, theta_true[:], theta_enc[:], thetadot_enc[:] = winch_readings_kernel(theta, theta_prev, offset, resolution,
                                                                          theta_enc_prev, rate)
    if friction:
        sensor_force_kernel(f, theta, thetadot, alpha_t, gamma_t, sigma, v_eps, dahl, tol, max_iterations,
                            sensor_gain, F_s_true)
    else:
        for i in range(m):
            F_s_true[i] = f[i] * gain[i]
    if noisy:
        F_s[:] = quantise_kernel(F_s_true, noise, k1, k0_ad, code_min, code_max, r1, r0)
    else:
        F_s[:] = quantise_kernel(F_s_true, None, k1, k0_ad, code_min, code_max, r1, r0)
    return 0, overload, moved

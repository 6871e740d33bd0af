"""Cables as unilateral visco-elastic elements between the pulley leave points and the platform.

Cable i pulls the platform anchor B_i = r + R b_i towards its leave point C_i with

    f_i = f_el(dq_i, l_t,i) + tau_c k_t,i(dq_i) (dq_dot_i)   if dq_i > 0, else 0,   f_i >= 0,

with the elongation dq = q - theta (2.24) (q = IK{x} (2.7), theta the winch's unstretched cable
length), the non-linear spring (2.16)-(2.17) over the total free length l_t = q + l_0 (2.14)
(cdpr_control.cable), its tangent stiffness k_t and a Kelvin-Voigt damping with time constant
tau_c (damping proportional to stiffness). A slack cable pulls nothing and no cable pushes.

Speed: the swivelling-pulley IK of cdpr_control.kinematics is evaluated at "refresh" poses only;
between refreshes the leave points c_i and wrap angles beta_i are frozen (the simplification of
thesis section 3.2) and q = |c_i - B_i| + beta_i r_p. The length error is second order in the
distance moved since the refresh (below 1e-8 m for 5 mm on IPAnema 3, 5e-7 m on the Mini), the
simulator refreshes after the anchors have moved ``refresh_distance``. The force law (2.17) depends
on the strain dq / l_t only, so it is tabulated once from cable.force_from_elongation and
cable.tangent_stiffness and interpolated (error below 2e-8 f_max). The per-step loop over the
cables is compiled with numba (it runs once per physics step; as numpy calls it would cost ten
times more, see benchmarks/bench_sim.py).
"""
from __future__ import annotations

import numba
import numpy as np

from cdpr_control import cable
from cdpr_control.kinematics import inverse_kinematics

_TABLE_POINTS = 20001


class CableModel:
    """The m cables of a robot; :meth:`wrench` gives the forces and their wrench on the platform.

    robot: cdpr_control.robot.Robot; damping_time [s]: tau_c; refresh_distance [m]: anchor motion
    after which the pulley IK is evaluated again. ``f_top`` [N]: end of the force table, the lower
    of 4 f_max and 0.99 sqrt(k0 / k2) (where (2.17) stops being monotone); strains beyond hold f_top
    and count in ``overloads``.
    """

    def __init__(self, robot, damping_time: float, refresh_distance: float = 5e-3):
        if not damping_time >= 0.0:
            raise ValueError(f"cable damping time must be >= 0 s, got {damping_time}")
        if not refresh_distance > 0.0:
            raise ValueError(f"refresh distance must be > 0 m, got {refresh_distance}")
        self.robot = robot
        self.damping_time = float(damping_time)
        self.refresh_distance = float(refresh_distance)
        c = robot.cable
        f_top = 4.0 * float(np.max(c.f_max))
        if c.k2 > 0.0:
            f_top = min(f_top, 0.99 * float(np.sqrt(c.k0 / c.k2)))
        self.f_top = f_top
        # strain e = dq / l_t <-> force: (2.17) at l_t = 1 m gives the strain directly
        f_grid = np.linspace(0.0, f_top, _TABLE_POINTS)
        self._e_grid = cable.elongation_from_force(robot, f_grid, 1.0)
        self._f_grid = f_grid
        self._k_grid = cable.tangent_stiffness(robot, np.maximum(f_grid, 1e-9), 1.0)   # N per unit strain
        self._e_top = float(self._e_grid[-1])
        self._b = np.ascontiguousarray(robot.b)
        self._l_0 = np.asarray(robot.l_0, dtype=float)
        self._r_p = np.asarray(robot.r_p, dtype=float)
        self.overloads = 0
        self._f, self._FT, self._anchors = np.empty(robot.m), np.empty(6), np.empty((robot.m, 3))
        self.c = None          # (m, 3) frozen leave points
        self.beta = None       # (m,) frozen wrap angles (2.6)
        self._anchors_at_refresh = None
        self.moved = 0.0        # largest anchor displacement since the refresh, at the last wrench [m]

    def strain_force(self, e) -> np.ndarray:
        """f(e) of (2.17) for strains e = dq / l_t from the table (0 for e <= 0)."""
        return np.interp(e, self._e_grid, self._f_grid)

    def refresh(self, x) -> None:
        """Evaluate the pulley IK (2.3)-(2.9) at pose x and freeze c_i, beta_i from it."""
        ik = inverse_kinematics(self.robot, x)
        self.c = np.array(ik.c)
        self.beta = np.array(ik.beta)
        self.beta.setflags(write=False)
        self._wrap = self.beta * self._r_p
        self._anchors_at_refresh = ik.Rb + np.asarray(x[:3], dtype=float)

    def needs_refresh(self) -> bool:
        """Whether the anchors of the last :meth:`wrench` moved more than refresh_distance (any axis)."""
        return self.moved > self.refresh_distance

    def wrench(self, r, R, v, omega, theta, thetadot):
        """Cable forces for platform origin r, rotation R, velocity v, angular velocity omega.

        theta, thetadot (m,): winch cable lengths and velocities. Returns (f (m,) [N], F (3,) force
        [N], T (3,) torque about the platform origin [N m], both in the base frame, anchors (m, 3)),
        views of buffers that the next call overwrites.
        """
        f, FT, anchors = self._f, self._FT, self._anchors
        overload, self.moved = _cable_wrench(
            self._b, self.c, self._wrap, self._l_0, self._e_grid, self._f_grid, self._k_grid, self.damping_time,
            r, R, v, omega, theta, thetadot, self._anchors_at_refresh, f, FT, anchors)
        if overload:
            self.overloads += 1
        return f, FT[:3], FT[3:], anchors


@numba.njit(cache=True)
def _cable_wrench(b, c, wrap, l_0, e_grid, f_grid, k_grid, tau, r, R, v, omega, theta, thetadot, ref, f, FT,
                  anchors):
    """The loop of CableModel.wrench (one pass over the cables).

    Returns (overload, largest anchor displacement from ``ref`` on any axis).
    """
    overload = False
    moved = 0.0
    n = e_grid.shape[0]
    FT[:] = 0.0
    for i in range(b.shape[0]):
        rb0 = R[0, 0] * b[i, 0] + R[0, 1] * b[i, 1] + R[0, 2] * b[i, 2]
        rb1 = R[1, 0] * b[i, 0] + R[1, 1] * b[i, 1] + R[1, 2] * b[i, 2]
        rb2 = R[2, 0] * b[i, 0] + R[2, 1] * b[i, 1] + R[2, 2] * b[i, 2]
        anchors[i, 0], anchors[i, 1], anchors[i, 2] = r[0] + rb0, r[1] + rb1, r[2] + rb2
        for k in range(3):
            moved = max(moved, abs(anchors[i, k] - ref[i, k]))
        l0, l1, l2 = c[i, 0] - anchors[i, 0], c[i, 1] - anchors[i, 1], c[i, 2] - anchors[i, 2]
        L = np.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
        q = L + wrap[i]
        l_t = q + l_0[i]
        e = (q - theta[i]) / l_t                      # strain of the elongation dq = q - theta (2.24)
        if e <= 0.0:                                  # slack: pulls nothing
            f[i] = 0.0
            continue
        j = np.searchsorted(e_grid, e)
        if j >= n:
            overload = True
            fi, ki = f_grid[n - 1], k_grid[n - 1]
        else:
            w = (e - e_grid[j - 1]) / (e_grid[j] - e_grid[j - 1])
            fi = f_grid[j - 1] + w * (f_grid[j] - f_grid[j - 1])
            ki = k_grid[j - 1] + w * (k_grid[j] - k_grid[j - 1])
        if tau > 0.0:
            # q_dot = -u . (v + omega x R b_i) (2.12); damping force tau k_t / l_t (q_dot - theta_dot)
            vp0 = v[0] + omega[1] * rb2 - omega[2] * rb1
            vp1 = v[1] + omega[2] * rb0 - omega[0] * rb2
            vp2 = v[2] + omega[0] * rb1 - omega[1] * rb0
            qdot = -(l0 * vp0 + l1 * vp1 + l2 * vp2) / L
            fi += tau * ki / l_t * (qdot - thetadot[i])
            if fi < 0.0:                              # a cable never pushes
                fi = 0.0
        f[i] = fi
        s = fi / L
        F0, F1, F2 = l0 * s, l1 * s, l2 * s
        FT[0] += F0
        FT[1] += F1
        FT[2] += F2
        FT[3] += rb1 * F2 - rb2 * F1
        FT[4] += rb2 * F0 - rb0 * F2
        FT[5] += rb0 * F1 - rb1 * F0
    return overload, moved

"""Cables as unilateral visco-elastic elements between the pulley leave points and the platform.

Cable i pulls the platform anchor B_i = r + R b_i towards its leave point C_i with

    f_i = f_el(dq_i, l_t,i) + tau_c k_t,i(dq_i) (dq_dot_i)   if dq_i > 0, else 0,   f_i >= 0,

with the elongation dq = q - theta (2.24) (q = IK{x} (2.7), theta the winch's unstretched cable
length), the non-linear spring (2.16)-(2.17) over the total free length l_t = q + l_0 (2.14)
(cdpr_control.model.cable), its tangent stiffness k_t and a Kelvin-Voigt damping with time constant
tau_c (damping proportional to stiffness). A slack cable pulls nothing and no cable pushes.

Speed: the swivelling-pulley IK of cdpr_control.model.kinematics is evaluated at "refresh" poses only;
between refreshes the leave points c_i and wrap angles beta_i are frozen (the simplification of
thesis section 3.2) and q = |c_i - B_i| + beta_i r_p. The length error is second order in the
distance moved since the refresh (below 1e-8 m for 5 mm on IPAnema 3, 5e-7 m on the Mini), the
simulator refreshes after the anchors have moved ``refresh_distance``. The force law (2.17) depends
on the strain dq / l_t only, so it is tabulated once from cable.force_from_elongation and
cable.tangent_stiffness and interpolated (error below 2e-8 f_max). The per-step loop over the
cables is compiled with numba (it runs once per physics step; as numpy calls it would cost ten
times more, see benchmarks/bench_sim.py).

Integration: a cable is stiff for the 1 ms physics step once it is loaded (the progressive
stiffness (2.16) grows 40-fold up to the table's end on the Mini) and the Kelvin-Voigt damping
grows with it, so the force of the start of a step, applied explicitly over the step, is unstable
under a hard push (energy grew without bound; damping forces of tens of kilonewtons).
:meth:`CableModel.implicit_wrench` makes the cable forces linearly implicit over the step (one 6x6
solve with the platform's mass matrix, docs/sim.md "Integration").
"""
from __future__ import annotations

import numpy as np

from cdpr_control.kernels.jit import njit

from cdpr_control.model import cable
from cdpr_control.kernels.model import cholesky_solve
from cdpr_control.model.kinematics import inverse_kinematics

_TABLE_POINTS = 20001


class CableModel:
    """The m cables of a robot; :meth:`wrench` gives the forces and their wrench on the platform.

    robot: cdpr_control.model.robot.Robot; damping_time [s]: tau_c; refresh_distance [m]: anchor motion
    after which the pulley IK is evaluated again; step [s]: the physics step h of
    :meth:`implicit_wrench`. ``f_top`` [N]: end of the force table, the lower of 4 f_max and
    0.99 sqrt(k0 / k2) (where (2.17) stops being monotone); strains beyond continue the force with
    the table's end slope (a stiff cable, not a constant force that would let a hard push carry the
    platform out of the frame) and count in ``overloads``.
    """

    def __init__(self, robot, damping_time: float, refresh_distance: float = 5e-3, step: float = 1e-3):
        if not damping_time >= 0.0:
            raise ValueError(f"cable damping time must be >= 0 s, got {damping_time}")
        if not refresh_distance > 0.0:
            raise ValueError(f"refresh distance must be > 0 m, got {refresh_distance}")
        if not step > 0.0:
            raise ValueError(f"physics step must be > 0 s, got {step}")
        self.step = float(step)
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
        # strain energy per unit free length, int_0^e f de (trapezoids on the table), for potential_energy
        self._w_grid = np.concatenate([[0.0], np.cumsum(0.5 * (f_grid[1:] + f_grid[:-1]) * np.diff(self._e_grid))])
        self._b = np.ascontiguousarray(robot.b)
        self._l_0 = np.asarray(robot.l_0, dtype=float)
        self._r_p = np.asarray(robot.r_p, dtype=float)
        self.overloads = 0
        self._f, self._FT, self._anchors = np.empty(robot.m), np.empty(6), np.empty((robot.m, 3))
        self._A, self._d = np.empty((robot.m, 6)), np.empty(robot.m)     # rows [u_i, Rb_i x u_i], implicit d_i
        self._FT_step = np.empty(6)
        self._hint = np.zeros(robot.m, dtype=np.int64)   # each cable's interval of the force table
        self.slackened = 0      # cables that went slack within a physics step (implicit_wrench)
        self.c = None          # (m, 3) frozen leave points
        self.beta = None       # (m,) frozen wrap angles (2.6)
        self._anchors_at_refresh = None
        self.moved = 0.0        # largest anchor displacement since the refresh, at the last wrench [m]

    def potential_energy(self, r, R, theta) -> float:
        """Elastic energy [J] stored in the cables at platform origin r, rotation R and unstretched
        lengths theta (m,): sum of l_t int_0^e f(e') de' over the taut cables (the integral of
        (2.17) along the elongation at constant l_t; beyond the table its linear continuation).
        With the frozen pulleys of the last :meth:`refresh`; for energy balances in tests."""
        anchors = np.asarray(r, dtype=float) + self._b @ np.asarray(R, dtype=float).T
        q = np.linalg.norm(self.c - anchors, axis=1) + self._wrap
        l_t = q + self._l_0
        e = (q - np.asarray(theta, dtype=float)) / l_t
        w = np.interp(e, self._e_grid, self._w_grid, left=0.0)
        over = e > self._e_top
        de = e[over] - self._e_top
        w[over] = self._w_grid[-1] + self._f_grid[-1] * de + 0.5 * self._k_grid[-1] * de * de
        return float(np.sum(np.where(e > 0.0, w * l_t, 0.0)))

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
        overload, self.moved = cable_wrench_kernel(
            self._b, self.c, self._wrap, self._l_0, self._e_grid, self._f_grid, self._k_grid, self.damping_time,
            self.step, r, R, v, omega, theta, thetadot, self._anchors_at_refresh, f, FT, anchors, self._A, self._d,
            self._hint)
        if overload:
            self.overloads += 1
        return f, FT[:3], FT[3:], anchors

    def wrench_arguments(self) -> tuple:
        """The arguments of cable_wrench_kernel but the platform state and the winches, for a caller that
        runs it inside its own compiled code (the simulator's period): (b, c, wrap, l_0, e_grid,
        f_grid, k_grid, tau_c, h, ref, f, FT, anchors, A, d, hint); it then sets ``moved`` and counts
        ``overloads`` as :meth:`wrench` does. c, wrap and ref change at :meth:`refresh`."""
        return (self._b, self.c, self._wrap, self._l_0, self._e_grid, self._f_grid, self._k_grid, self.damping_time,
                self.step, self._anchors_at_refresh, self._f, self._FT, self._anchors, self._A, self._d, self._hint)

    def linearisation(self) -> tuple[np.ndarray, np.ndarray]:
        """(A (m, 6), d (m,)) of the last :meth:`wrench`, views: rows [u_i, R b_i x u_i] (the
        transposed structure matrix) and the implicit coefficients d_i of :meth:`implicit_wrench`."""
        return self._A, self._d

    def implicit_wrench(self, f, A, d, thetadot_0, thetadot_1, mass, c_p, J_p, R, g, w_ext):
        """The cable wrench to apply over the next physics step (force (3,), torque (3,) about the
        platform origin, base frame): the forces f (m,) of :meth:`wrench` with its linearisation
        (A, d) and the winch velocities thetadot_0 -> thetadot_1 (m,) over the step, made implicit over
        the step for a platform of ``mass`` [kg] with its centre of
        gravity at c_p (3,) and inertia J_p (3, 3) about it (platform frame), at rotation R, under
        gravity g (3,) and the external wrench w_ext (6,) about its origin (base frame).

        Why: the explicit force of the start of the step is unstable once the cables are stiff
        enough (omega h ~ 1, the progressive cable near its rated force and beyond, a hard push):
        energy grows and the damping force jumps to kilonewtons. Here each taut cable acts over the
        step with f_i + d_i ds_i, ds_i = -A_i dxi - dthetadot_i the change of its elongation rate
        (2.12), (2.24) over the step (dxi: the platform twist's) and
        d_i = (h/4 + tau_c) k_t,i: the spring of Newmark's average acceleration (no numerical
        damping) and an implicit (backward Euler) damper, which cannot overshoot: stable for any
        stiffness, so energy cannot grow; a cable that would push is slack (unilateral, f >= 0).
        """
        self.slackened += implicit_wrench_kernel(A, f, d, thetadot_0, thetadot_1, self.step, mass, c_p, J_p, R, g,
                                           w_ext, self._FT_step)
        FT = self._FT_step
        return FT[:3], FT[3:]


@njit
def cable_wrench_kernel(b, c, wrap, l_0, e_grid, f_grid, k_grid, tau, h, r, R, v, omega, theta, thetadot, ref, f, FT,
                  anchors, A, d, hint):
    """The loop of CableModel.wrench (one pass over the cables).

    Fills f (m,), the wrench FT = A^T f (6,), the anchors (m, 3), the rows A_i = [u_i, Rb_i x u_i]
    (the transposed structure matrix, (2.11)) and the coefficients d_i = (h/4 + tau) k_t,i [N s/m]
    of the implicit step (see CableModel.implicit_wrench), 0 for a slack cable. hint (m,): each
    cable's table interval of the last call, updated.
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
        u0, u1, u2 = l0 / L, l1 / L, l2 / L
        A[i, 0], A[i, 1], A[i, 2] = u0, u1, u2
        A[i, 3], A[i, 4], A[i, 5] = rb1 * u2 - rb2 * u1, rb2 * u0 - rb0 * u2, rb0 * u1 - rb1 * u0
        d[i] = 0.0
        q = L + wrap[i]
        l_t = q + l_0[i]
        e = (q - theta[i]) / l_t                      # strain of the elongation dq = q - theta (2.24)
        if e <= 0.0:                                  # slack: pulls nothing
            f[i] = 0.0
            continue
        # np.searchsorted(e_grid, e), the same j, tried first at the cable's last interval: the strain
        # moves little between steps, and the binary search reads some 15 entries spread over the
        # 160 kB table per cable, cache misses when the node graph shares the core
        j = hint[i]
        if not (0 < j < n and e_grid[j - 1] < e <= e_grid[j]):
            j = np.searchsorted(e_grid, e)
            hint[i] = j
        if j >= n:                                    # beyond the table: continued with its end slope
            overload = True
            ki = k_grid[n - 1]
            fi = f_grid[n - 1] + ki * (e - e_grid[n - 1])
        else:
            w = (e - e_grid[j - 1]) / (e_grid[j] - e_grid[j - 1])
            fi = f_grid[j - 1] + w * (f_grid[j] - f_grid[j - 1])
            ki = k_grid[j - 1] + w * (k_grid[j] - k_grid[j - 1])
        k_l = ki / l_t                                # tangent stiffness [N/m] (2.20)
        if tau > 0.0:
            # q_dot = -u . (v + omega x R b_i) (2.12); damping force tau k_t / l_t (q_dot - theta_dot)
            vp0 = v[0] + omega[1] * rb2 - omega[2] * rb1
            vp1 = v[1] + omega[2] * rb0 - omega[0] * rb2
            vp2 = v[2] + omega[0] * rb1 - omega[1] * rb0
            qdot = -(u0 * vp0 + u1 * vp1 + u2 * vp2)
            fi += tau * k_l * (qdot - thetadot[i])
            if fi < 0.0:                              # a cable never pushes
                fi = 0.0
        if fi > 0.0:
            d[i] = (0.25 * h + tau) * k_l
        f[i] = fi
        FT[0] += u0 * fi
        FT[1] += u1 * fi
        FT[2] += u2 * fi
        FT[3] += A[i, 3] * fi
        FT[4] += A[i, 4] * fi
        FT[5] += A[i, 5] * fi
    return overload, moved


@njit
def implicit_wrench_kernel(A, f, d, thetadot_0, thetadot_1, h, mass, c_p, J_p, R, g, w_ext, FT):
    """Cable wrench over one physics step of length h, linearly implicit in the cable forces.

    The platform twist xi = [v; omega] of its origin changes by dxi over the step; M is its spatial
    mass matrix about the origin in the base frame (mass, centre of gravity at rho = R c_p from the
    origin, inertia R J_p R^T about the centre of gravity; c_p, J_p in the platform frame); w_other
    is gravity g (3,) and the external wrench w_ext (6,) about the origin. Each taut cable's force
    over the step is taken at the end-of-step elongation rate and a quarter step further along the
    elongation, f_i' = f_i + d_i ds_i with ds_i = -A_i dxi - dthetadot_i (2.12), (2.24) (the winch
    velocity changes from thetadot_0 to thetadot_1 over the step) and
    d_i = (h/4 + tau_c) k_t,i (a Newmark average-acceleration spring, a backward Euler damper); so
    (M + h A^T D A) dxi = h (A^T (f - D dthetadot) + w_other). A cable whose f_i' would be
    negative is slack over the step (f_i' = 0) and the system is solved again without it. Fills
    FT = A^T f' and returns the number of cables that went slack in the step.
    """
    m = A.shape[0]
    rho = np.zeros(3)
    RJ = np.zeros((3, 3))
    J = np.zeros((3, 3))
    for a in range(3):                                # rho = R c_p, J = R J_p R^T (loops: no BLAS call)
        for k in range(3):
            rho[a] += R[a, k] * c_p[k]
            for b in range(3):
                RJ[a, b] += R[a, k] * J_p[k, b]
    for a in range(3):
        for b in range(3):
            for k in range(3):
                J[a, b] += RJ[a, k] * R[b, k]
    w_other = np.empty(6)
    for k in range(3):
        w_other[k] = mass * g[k] + w_ext[k]
    w_other[3] = mass * (rho[1] * g[2] - rho[2] * g[1]) + w_ext[3]
    w_other[4] = mass * (rho[2] * g[0] - rho[0] * g[2]) + w_ext[4]
    w_other[5] = mass * (rho[0] * g[1] - rho[1] * g[0]) + w_ext[5]
    M = np.zeros((6, 6))
    for k in range(3):
        M[k, k] = mass
    # [rho]x blocks: M = [[m I, -m [rho]x], [m [rho]x, J - m [rho]x [rho]x]]
    S = np.zeros((3, 3))
    S[0, 1], S[0, 2], S[1, 0], S[1, 2], S[2, 0], S[2, 1] = -rho[2], rho[1], rho[2], -rho[0], -rho[1], rho[0]
    for a in range(3):
        for b in range(3):
            M[a, 3 + b] = -mass * S[a, b]
            M[3 + a, b] = mass * S[a, b]
            ss = 0.0
            for k in range(3):
                ss += S[a, k] * S[k, b]
            M[3 + a, 3 + b] = J[a, b] - mass * ss
    active = np.empty(m, dtype=np.bool_)
    for i in range(m):
        active[i] = d[i] > 0.0
    fn = np.empty(m)
    for i in range(m):
        fn[i] = f[i] - d[i] * (thetadot_1[i] - thetadot_0[i])     # the winch's velocity change over the step
    K = np.empty((6, 6))
    rhs = np.empty(6)
    x = np.empty(6)
    dropped = 0
    for _ in range(m + 1):
        for a in range(6):
            rhs[a] = w_other[a]
            for b in range(6):
                K[a, b] = M[a, b]
        for i in range(m):
            for a in range(6):
                rhs[a] += A[i, a] * fn[i]
            if active[i]:
                hd = h * d[i]
                for a in range(6):
                    ha = hd * A[i, a]
                    for b in range(a, 6):
                        K[a, b] += ha * A[i, b]
        for a in range(6):
            rhs[a] *= h
            for b in range(a):
                K[a, b] = K[b, a]
        cholesky_solve(K, rhs, x, K)                   # in place: K becomes its Cholesky factor
        again = False
        for i in range(m):
            if active[i]:
                s = 0.0
                for a in range(6):
                    s += A[i, a] * x[a]
                fi = fn[i] - d[i] * s
                if fi < 0.0:
                    active[i] = False
                    fn[i] = 0.0
                    dropped += 1
                    again = True
        if not again:
            break
    FT[:] = 0.0
    for i in range(m):
        fi = fn[i]
        if active[i]:
            s = 0.0
            for a in range(6):
                s += A[i, a] * x[a]
            fi = fn[i] - d[i] * s
        for a in range(6):
            FT[a] += A[i, a] * fi
    return dropped

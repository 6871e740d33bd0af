"""The float fast paths of the load compensation (4.4)-(4.6) and the hybrid force controller (5.1)
against their numpy formulation, bit for bit, on random input sequences of both robots.

The per-period arithmetic of these stages runs on plain floats where numpy's element-wise operations
on 2-12 numbers cost mostly call overhead; the references below are the numpy formulation they
replaced (the moving average, the set-point delay and the identification on arrays; the contact
force through LowPass). Dot products and matrix products stay numpy's in both (their summation
order is BLAS's), so every number must come out identical, not merely close.
"""
import math

import numpy as np
import pytest

from cdpr_control import kernels
from cdpr_control.control import load_compensation as lcm
from cdpr_control.model.dynamics import platform_wrench
from cdpr_control.control.filters import LowPass
from cdpr_control.force_distribution import ForceDistributor
from cdpr_control.control.hybrid_force_control import HPFCParams, HybridForceControl, contact_force
from cdpr_control.model.kinematics import inverse_kinematics, rotation_matrix
from cdpr_control.control.load_compensation import (COG_DECIMATION, REFERENCE_FRACTION, LoadCompensation,
    LoadCompensationParams, MovingAverage, compensating_wrench, cable_stiffness_model, compliance,
    mass_estimate, secant_offset, twist_to_pose_offset)
from cdpr_control.control.safety import all_finite


def same(a, b) -> bool:
    """Bit-equal: the same float64 bytes (so -0.0 differs from 0.0 and a NaN equals itself)."""
    if a is None or b is None:
        return a is None and b is None
    return np.asarray(a, dtype=float).tobytes() == np.asarray(b, dtype=float).tobytes()


class NumpyMovingAverage:
    """The moving average on numpy arrays: MovingAverage's arithmetic as it was written first."""

    def __init__(self, T, dt, size=1):
        self.dt, self.size = dt, size
        self.buffer = self.sum = None
        self.index = 0
        self.set_window(T)

    def set_window(self, T):
        mean = self.mean if self.buffer is not None else None
        self.T = T
        self.n = max(int(round(T / self.dt)), 1)
        if mean is not None:
            self.reset(mean)

    def reset(self, value=None):
        self.buffer = None if value is None else np.tile(np.asarray(value, dtype=float), (self.n, 1))
        self.sum = None if value is None else self.buffer.sum(axis=0)
        self.index = 0

    @property
    def mean(self):
        return None if self.buffer is None else self.sum / self.n

    def update(self, value):
        value = np.asarray(value, dtype=float).reshape(self.size)
        if self.buffer is None:
            self.reset(value)
        else:
            self.sum += value - self.buffer[self.index]
            self.buffer[self.index] = value
            self.index = (self.index + 1) % self.n
            if self.index == 0:
                self.sum = self.buffer.sum(axis=0)
        return self.mean


class NumpyLoadCompensation(LoadCompensation):
    """LoadCompensation with its per-period bookkeeping on numpy arrays (the delay line, the moving
    averages, the identification (4.4) and the force window), as it was written first; the offset
    (4.5)-(4.6) after the window is the library's own (LoadCompensation._offset)."""

    def __init__(self, robot, dt, params=None, monkeypatch=None):
        monkeypatch.setattr(lcm, "MovingAverage", NumpyMovingAverage)     # the filters __init__ builds
        super().__init__(robot, dt, params)
        monkeypatch.undo()

    def set_params(self, p):
        super().set_params(p)
        if isinstance(self.delay, list):                # rebuilt by the library as rows of floats
            self.delay = np.array(self.delay, dtype=float)

    def _shifted(self, x_d, xdot_d, xddot_d):
        sample = np.concatenate((x_d, xdot_d, xddot_d))
        if self.delay is None:
            self.delay = np.tile(sample, (self._delay_n + 1, 1))
        self.delay[self.delay_index] = sample
        self.delay_index = (self.delay_index + 1) % len(self.delay)
        return self.delay[self.delay_index]

    def identify(self, x_d, xdot_d, xddot_d, f, AT, x=None):
        shifted = self._shifted(x_d, xdot_d, xddot_d)
        xs, xdots, xddots = shifted[:6], shifted[6:12], shifted[12:]
        w = -np.asarray(AT) @ np.asarray(f, dtype=float)
        if self.m_hat is None:
            self.m_hat = self.m_p
        if not all_finite(w):
            self.guarded = True
            return
        w_z, a = self.wrench_filter.update([w[2], xddots[2]])
        self.pose_acceleration = False
        if self.params.acceleration_source == "estimated" and x is not None and math.isfinite(x[2]):
            estimated = self._estimated_acceleration(float(x[2]), float(w[2]))
            if estimated is not None:
                w_z, a = estimated
                self.pose_acceleration = True
        estimate = mass_estimate(float(w_z), float(a), float(self.robot.gravity[2]), self.params.accel_guard)
        self.guarded = estimate is None
        if self.guarded:
            return
        self.m_hat = float(estimate) - self.m_tare
        self.samples += 1
        if self.samples % COG_DECIMATION:
            return
        w_p = w - kernels.platform_wrench(self.robot, xs, xdots, xddots)
        RT = rotation_matrix(xs[3:]).T
        f_p, tau_p = RT @ w_p[:3], RT @ w_p[3:]
        S = np.array([[0.0, -f_p[2], f_p[1]], [f_p[2], 0.0, -f_p[0]], [-f_p[1], f_p[0], 0.0]])
        self.cog_filter.update(np.concatenate(((S.T @ S).ravel(), -S.T @ tau_p)))

    def _window_forces(self, f, ik):
        finite = all_finite(f)
        if finite:
            f = self.force_filter.update(f)
            if not self.guarded and abs(self.m_c) <= REFERENCE_FRACTION * self.m_p:
                self.f_ref = f.copy()
            if self.settlement.ratio > 0.0:
                if self.settlement.f_settled is None and self.f_ref is not None:
                    self.settlement.reset(self.f_ref)
                self.settlement.update(f, lcm.cable.total_free_length(self.robot, ik.q))
        return f, finite


@pytest.mark.parametrize("size, T", [(1, 0.01), (2, 0.24), (8, 0.003), (12, 0.001), (2, 0.0)])
def test_moving_average_floats_equal_the_numpy_formulation(size, T):
    rng = np.random.default_rng(size)
    fast, ref = MovingAverage(T, 1e-3, size), NumpyMovingAverage(T, 1e-3, size)
    for k in range(1500):
        if k == 700:                                    # a live window change restarts at the mean
            fast.set_window(2.5 * T + 0.002)
            ref.set_window(2.5 * T + 0.002)
        value = rng.normal(size=size) * 10.0 ** rng.integers(-3, 4)
        if k % 3:
            assert same(fast.push(value.tolist()), ref.update(value))
        else:
            assert same(fast.update(value), ref.update(value.copy()))
        assert same(fast.mean, ref.mean)
    fast.reset([1.5] * size)
    ref.reset([1.5] * size)
    assert same(fast.mean, ref.mean)


def _inputs(robot, n, seed, payload_steps=True):
    """A set-point moving about home, the cable forces that carry the platform (and a payload
    stepping on and off) with sensor noise, the estimated pose, and a few invalid samples."""
    rng = np.random.default_rng(seed)
    home = np.asarray(robot.home, dtype=float)
    size = 0.01 * float(robot.frame_size[0])
    fmin = np.asarray(robot.cable.f_min, dtype=float) * np.ones(robot.m)
    distributor = ForceDistributor(robot.m, robot.cable.f_min, robot.cable.f_max, method="qp")
    out = []
    for k in range(n):
        t = k * 1e-3
        x = home + np.array([size * math.sin(3.0 * t), 0.0, size * (1.0 - math.cos(3.0 * t)), 0.01 * math.sin(t),
                             0.0, 0.005 * math.cos(2.0 * t)])
        xd = np.array([3.0 * size * math.cos(3.0 * t), 0.0, 3.0 * size * math.sin(3.0 * t), 0.01 * math.cos(t),
                       0.0, -0.01 * math.sin(2.0 * t)])
        xdd = np.array([-9.0 * size * math.sin(3.0 * t), 0.0, 9.0 * size * math.cos(3.0 * t), 0.0, 0.0, 0.0])
        m_c = (0.6 * robot.platform.mass if (k // 400) % 2 else 0.0) if payload_steps else 0.0
        w = platform_wrench(robot, x, xd, xdd) + lcm.payload_wrench(robot, x, xd, xdd, m_c, (0.02, -0.01, 0.0))
        f = distributor.solve(inverse_kinematics(robot, x).AT, w, 1e-3).f + rng.normal(size=robot.m) * 0.05 * fmin
        if k % 397 == 5:
            f[k % robot.m] = np.nan                              # an invalid reading: held
        if k % 533 == 7:
            xdd = xdd + np.array([0.0, 0.0, -9.0, 0.0, 0.0, 0.0])   # near free fall: the estimate is guarded
        x_est = x + rng.normal(size=6) * 1e-6
        out.append((x, xd, xdd, f, x_est))
    return out


PARAMS = [
    LoadCompensationParams(enabled=False, tare_at_start=True),
    LoadCompensationParams(enabled=True, torque=True, cog_min_mass=0.0, settlement_ratio=0.5, T_output=0.05),
    LoadCompensationParams(enabled=True, offset_model="tangent", stiffness_model="linear",
                           acceleration_source="commanded", time_shift=0.005, T_filter=0.05),
]


@pytest.mark.parametrize("case", range(len(PARAMS)))
def test_load_compensation_floats_equal_the_numpy_formulation(robot, case, monkeypatch):  # noqa: F811
    params = PARAMS[case]
    fast = LoadCompensation(robot, 1e-3, params)
    ref = NumpyLoadCompensation(robot, 1e-3, params, monkeypatch)
    for k, (x, xd, xdd, f, x_est) in enumerate(_inputs(robot, 1600, seed=case)):
        if k == 900:                           # live changes of the windows and the delay line
            changed = LoadCompensationParams(**{**params.__dict__, "T_filter": 0.1, "time_shift": 0.02})
            fast.set_params(changed)
            ref.set_params(changed)
        if k == 1000:
            assert same(fast.tare(0.0), ref.tare(0.0))
        out_fast = fast.update(x, xd, xdd, f, x_est)
        out_ref = ref.update(x, xd, xdd, f, x_est)
        assert same(out_fast, out_ref), k
        assert same(fast.m_hat, ref.m_hat) and same(fast.m_c, ref.m_c) and fast.guarded == ref.guarded
        assert same(fast.cog, ref.cog) and same(fast.x_target, ref.x_target)
        assert np.array_equal(fast.rate_limited, ref.rate_limited)
        assert same(fast.f_ref, ref.f_ref) and same(fast.settlement.s, ref.settlement.s)
        assert same(fast.payload_wrench(x, xd, xdd), ref.payload_wrench(x, xd, xdd))


def test_hybrid_force_control_contact_force_and_F_equal_the_numpy_formulation(robot):  # noqa: F811
    """Through approach, contact, tare, a turned force axis, invalid wrenches and the release: the
    filtered contact force is LowPass of contact_force (3,), F_d and F the dot products with z_t."""
    params = HPFCParams(K_p=30000.0, T_i=0.3, F_th=1.0, v_max=0.02, a_max=1.0, x_max=0.02, T_F=0.01)
    hpfc = HybridForceControl(robot, 1e-3, params, enabled=True)
    reference = LowPass(params.T_F, 1e-3)
    rng = np.random.default_rng(3)
    weight = robot.platform.mass * np.asarray(robot.gravity, dtype=float)
    offset = rng.normal(size=3) * 0.2                        # the sensors' offset, tared at an approach
    F_d0 = np.array([0.0, 0.0, -10.0])
    for k in range(3000):
        if k == 1200:
            F_d0 = np.array([3.0, -1.0, -9.0])                 # a turned force axis
        if k == 2200:
            hpfc.enabled = False                               # release
        z = -F_d0 / np.linalg.norm(F_d0)                       # the surface's normal
        depth = max(0.0, hpfc.x_t - 0.002)                     # a stiff floor 2 mm ahead
        w = np.r_[weight - offset + 30000.0 * depth * z + rng.normal(size=3) * 0.05, rng.normal(size=3) * 0.01]
        if k % 211 == 3:
            w[k % 6] = np.nan                                  # an invalid wrench: the last estimate kept
        s = hpfc.update(F_d0, w)
        if all_finite(w):
            reference.update(contact_force(w, hpfc.mass, robot.gravity))
        assert same(hpfc.force_filter.y, reference.y), k
        F_vec = reference.y - hpfc.F_tare
        assert same(s.F_vec, F_vec) and same(s.F, float(s.z_t @ F_vec))
        assert same(s.F_d, float(s.z_t @ s.F_d0))
    assert s.state == "I"


def test_low_pass_on_floats_is_update_bit_for_bit():
    """LowPass.update_floats (1-3 values as floats) gives update's numbers, for vectors and a scalar."""
    from cdpr_control.control.filters import LowPass
    rng = np.random.default_rng(5)
    for size in (1, 3):
        for T in (0.0, 0.01, 0.3):
            a, b = LowPass(T, 1e-3), LowPass(T, 1e-3)
            for _ in range(500):
                u = rng.normal(0.0, 10.0, size) * rng.choice([1.0, 1e-6, 1e6])
                ref = a.update(u.copy())
                out = b.update_floats(u.tolist())
                assert np.array(out).tobytes() == ref.tobytes() == b.y.tobytes()
    scalar_ref, scalar = LowPass(0.05, 1e-3), LowPass(0.05, 1e-3)
    for u in rng.normal(0.0, 5.0, 300).tolist():
        assert np.float64(scalar.update_floats((u,))[0]).tobytes() == np.float64(scalar_ref.update(u)).tobytes()

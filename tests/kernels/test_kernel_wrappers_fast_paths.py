"""The kernel wrappers' fast paths give the same numbers, bit for bit, as what they replace: the
friction compensation's pulley tables kept while β_np's bytes repeat against tables computed every
call, its Dahl step as a loop against the compiled numpy reference (kernels/friction.py), and
kernels.vector's one-flag test against the copy it replaces."""
import sys

import numpy as np
import pytest

from cdpr_control import kernels
from cdpr_control.model.friction import PulleyFriction
from cdpr_control.model.robot import load_robot

kfriction = sys.modules["cdpr_control.kernels.friction"]


def _forget_tables():
    kfriction._tables_memo.clear()


def _betas(robot, rng):
    """A sequence of wrap angles: repeats, a change, the same values again, a sign of zero flipped."""
    beta = kernels.inverse_kinematics(robot, np.asarray(robot.home, dtype=float)).beta.copy()
    other = beta + rng.normal(scale=0.05, size=beta.shape)
    zero = beta.copy()
    zero[0] = 0.0
    neg_zero = zero.copy()
    neg_zero[0] = -0.0
    return [beta, beta.copy(), beta, other, other.copy(), beta.copy(), zero, neg_zero, neg_zero.copy(), zero,
            list(beta), beta]


def test_friction_tables_kept_while_beta_repeats_bit_for_bit(robot):
    """Two models fed the same samples, one with the kept tables, one with the tables computed every
    call: the same forces and the same Dahl state, bit for bit, also with a second model's calls in
    between (the tables follow the series)."""
    rng = np.random.default_rng(11)
    q = kernels.inverse_kinematics(robot, np.asarray(robot.home, dtype=float)).q
    kept, fresh, between = (PulleyFriction.from_robot(robot, q) for _ in range(3))
    hits = 0
    for k, beta in enumerate(_betas(robot, rng) * 2):
        f_w = rng.uniform(50.0, 500.0, robot.m)
        theta = q + rng.normal(scale=1e-3, size=robot.m)
        thetadot = rng.normal(scale=0.01, size=robot.m) * (k % 3 != 0)
        if k % 5 == 4:
            kernels.friction_platform_force(between, f_w, theta, thetadot, beta)
        memo = kfriction._tables_memo
        hits_before = memo.value
        out = kernels.friction_platform_force(kept, f_w, theta, thetadot, beta)
        hits += memo.value is hits_before
        kept_tables = memo.key, memo.value
        _forget_tables()
        ref = kernels.friction_platform_force(fresh, f_w, theta, thetadot, beta)
        memo.key, memo.value = kept_tables
        assert out.tobytes() == ref.tobytes()
        assert kept.dahl.state.tobytes() == fresh.dahl.state.tobytes()
    assert hits >= 8                        # the kept tables did serve the repeats

def test_friction_tables_follow_sign_of_zero_and_values():
    """The kept tables are those of β's exact bytes: -0.0 after 0.0 and a changed value compute
    again, equal to a fresh computation."""
    robot = load_robot("ipanema3_mini")
    series = PulleyFriction.from_robot(robot, np.zeros(robot.m)).series
    beta = np.linspace(-0.3, 0.3, robot.m)
    beta[0] = 0.0
    for b in (beta, beta.copy(), np.where(beta == 0.0, -0.0, beta), beta + 1e-12, beta):
        alpha, gamma = kfriction._series_tables(series, b)
        _forget_tables()
        alpha_ref, gamma_ref = kfriction._series_tables(series, b)
        assert alpha.tobytes() == alpha_ref.tobytes() and gamma.tobytes() == gamma_ref.tobytes()
        assert kfriction._tables_memo.key[1] == np.asarray(b, dtype=float).tobytes()


def test_vector_passes_a_kernel_array_and_copies_the_rest():
    """kernels.vector returns a writeable aligned C-contiguous float64 array itself, and an equal
    copy of anything else (a view with strides, read-only, another dtype, unaligned, a list)."""
    vector = sys.modules["cdpr_control.kernels.robot_data"].vector
    a = np.array([0.5, -0.0, np.nan, 1e30, -3.25, 7.0])
    assert vector(a) is a
    read_only = a.copy()
    read_only.flags.writeable = False
    raw = np.zeros(a.nbytes + 1, dtype=np.uint8)
    unaligned = raw[1:].view(float)
    unaligned[:] = a
    others = [a[::2], read_only, a.astype(np.float32), unaligned, a.tolist(), a[::-1], a.reshape(2, 3).T]
    assert not unaligned.flags.aligned
    for v in others:
        out = vector(v)
        assert out is not v
        assert out.dtype == np.float64 and out.flags.c_contiguous and out.flags.writeable and out.flags.aligned
        assert out.tobytes() == np.array(v, dtype=float, order="C").tobytes()


def test_friction_step_loop_equals_the_compiled_reference_bit_for_bit():
    """kernels.friction.platform_force_kernel against friction.platform_force_step compiled by numba
    (what the wrapper ran before): the same forces and Dahl state, bit for bit, over a random walk
    with standstill, direction changes, speeds at v_eps, signed zeros and a NaN."""
    from cdpr_control.kernels.jit import njit
    from cdpr_control.model import friction as np_friction

    # numba.njit with the project's disk cache (the simulator compiles the same function so): loaded,
    # not compiled again in every run (the compile was most of this test's time)
    reference = njit(np_friction.platform_force_step)
    rng = np.random.default_rng(7)
    m = 8
    alpha_t, gamma_t = rng.uniform(0.8, 1.3, (3, m)), rng.uniform(-5.0, 5.0, (3, m))
    sigma = rng.uniform(1e4, 1e6, m)
    for v_eps in (0.0, 1e-3):
        state = np.zeros((5, m))
        state[3] = rng.uniform(0.5, 2.0, m)
        state_ref = state.copy()
        theta = state[3].copy()
        for k in range(300):
            thetadot = rng.normal(scale=2e-3, size=m) * (k % 7 != 0)
            thetadot[k % m] = (v_eps, -v_eps, 0.0, -0.0, 2 * v_eps + 1e-4, thetadot[k % m])[k % 6]
            if k == 150:
                thetadot[3] = np.nan
            theta = theta + thetadot * 1e-3
            f_w = rng.uniform(-20.0, 800.0, m)
            f = np.empty(m)
            kfriction.platform_force_kernel(f_w, theta, thetadot, alpha_t, gamma_t, sigma, v_eps, state, f)
            f_ref = reference(f_w, theta, thetadot, alpha_t, gamma_t, sigma, v_eps, state_ref)
            assert f.tobytes() == f_ref.tobytes(), k
            assert state.tobytes() == state_ref.tobytes(), k

"""The simulator's per-period shortcuts give the numbers of the numpy expressions they replace, bit for bit."""
import numpy as np

from cdpr_control.model.kinematics import cross
from cdpr_control.model.robot import load_robot
from cdpr_sim.plant import Settlement
from cdpr_sim.sensors import Encoder, ForceSensor
from cdpr_sim.simulator import winch_readings_kernel

RNG = np.random.default_rng(7)


def test_cross_of_two_vectors_is_np_cross():
    a, b = RNG.normal(size=(2, 1000, 3))
    for x, y in zip(a, b):
        assert np.array_equal(cross(x, y), np.cross(x, y))
    assert np.array_equal(cross(a, b), np.cross(a, b))          # the batched form: the same numbers


def test_settlement_is_its_array_form():
    s = Settlement(ratio=0.3, T=2.0, k0=6e5, dt=1e-3, m=8)
    s.reset(np.full(8, 500.0))
    reference = np.zeros(8)
    for _ in range(500):
        f, l_t = RNG.uniform(0.0, 2000.0, 8), RNG.uniform(0.5, 10.0, 8)
        target = s.ratio * l_t * np.maximum(f - s.f_settled, 0.0) / s.k0
        reference += s.alpha * np.maximum(target - reference, 0.0)
        assert np.array_equal(s.update(f, l_t), reference)


def test_encoder_and_winch_readings_are_their_array_forms():
    for resolution in (5.99e-8, 0.0):
        enc = Encoder(resolution)
        theta, prev, offset = RNG.uniform(0.5, 3.0, (3, 8))
        enc_prev = enc.read(prev + offset)
        reading = np.rint(theta / resolution) * resolution if resolution else theta
        assert np.array_equal(enc.read(theta), reading)
        rate = 1.0 / 1e-3
        thetadot, theta_true, theta_enc, thetadot_enc = winch_readings_kernel(theta, prev, offset, resolution, enc_prev, rate)
        assert np.array_equal(thetadot, (theta - prev) * rate)
        assert np.array_equal(theta_true, theta + offset)
        assert np.array_equal(theta_enc, enc.read(theta + offset))
        assert np.array_equal(thetadot_enc, (enc.read(theta + offset) - enc_prev) * rate)


def test_force_sensor_noise_as_added_before():
    s = load_robot("ipanema3_mini").sensor
    sensor = ForceSensor(s, 8, np.random.default_rng(3))
    quiet = ForceSensor(s, 8, np.random.default_rng(0), noise_std=0.0)
    noise = np.random.default_rng(3)
    for _ in range(200):
        F = RNG.uniform(-10.0, 200.0, 8)
        assert np.array_equal(sensor.read(F), quiet.read(F + noise.normal(0.0, sensor.noise_std, 8)))

"""Winches and sensors of the simulator: drive response, pulley friction, AD conversion, determinism."""
import numpy as np
import pytest

from cdpr_sim.drive_models import DriveModel
from cdpr_control.model.friction import PulleyFriction, winch_force_from_sensor
from cdpr_control.model.robot import load_robot
from cdpr_sim.sensors import Encoder, ForceSensor
from cdpr_sim.simulator import SimConfig, Simulator, pretension_lengths
from cdpr_sim.startup import startup_forces


def _sim(name, **config):
    """The perfect-model plant: these tests check the simulator against the model equations."""
    config.setdefault("plant", "nominal")
    robot = load_robot(name)
    x = robot.home.copy()
    theta = pretension_lengths(robot, x, startup_forces(robot, x, 0.5))
    return Simulator(robot, SimConfig(**config), x0=x, theta0=theta), theta


@pytest.mark.parametrize("name", ["ipanema3", "ipanema3_mini"])
def test_sine_sweep_on_one_winch_reproduces_the_drive_model(name):
    """Stepped sine on winch 1 (platform attached): gain within 0.5 dB, phase within 5 deg of G_a."""
    sim, theta0 = _sim(name, noise_std=0.0)
    period = sim.config.period
    model = DriveModel.from_robot(sim.robot, period)
    amplitude = 2e-3
    for freq in (1.0, 5.0, 12.0):
        w = 2 * np.pi * freq
        n = int(round(2.0 / period))
        theta_d = np.tile(theta0, (n, 1))
        t_cmd = sim.t + period * np.arange(n)
        theta_d[:, 0] += amplitude * np.sin(w * t_cmd)
        theta = np.array([sim.step(td).theta[0] for td in theta_d])
        t = t_cmd + period                                  # outputs hold at the end of each period
        keep = t >= t[0] + 0.5
        basis = np.column_stack([np.sin(w * t[keep]), np.cos(w * t[keep]), np.ones(keep.sum())])
        a, b, _ = np.linalg.lstsq(basis, theta[keep], rcond=None)[0]
        G = (a + 1j * b) / amplitude
        G_model = model.transfer_function(1j * w)
        assert 20 * np.log10(abs(G) / abs(G_model)) == pytest.approx(0.0, abs=0.5)
        assert np.rad2deg(np.angle(G / G_model)) == pytest.approx(0.0, abs=5.0)


def test_sensor_force_is_the_platform_force_through_the_friction_model():
    """F_s differs from f by the pulley friction: the compensation (3.44) on F_s gives f back."""
    sim, theta0 = _sim("ipanema3_mini", noise_std=0.0)
    period = sim.config.period
    robot = sim.robot
    compensation = PulleyFriction.from_robot(robot, sim.output.theta_true, sim.config.friction_v_eps)
    # move the platform up and down by 2 cm with 0.5 s pauses: winches reverse and stand still
    z = 0.02 * np.sin(np.linspace(0, 4 * np.pi, 2000))
    z = np.concatenate([z[:500], np.full(500, z[499]), z[500:]])
    worst, prev = 0.0, sim.output.theta_true
    frictions = []
    for dz in z:
        x = robot.home + np.array([0, 0, dz, 0, 0, 0])
        out = sim.step(pretension_lengths(robot, x, startup_forces(robot, x, 0.5)))
        thetadot = (out.theta_true - prev) / period
        prev = out.theta_true
        f_hat = compensation.platform_force(out.F_s_true, out.theta_true, thetadot, out.beta)
        worst = max(worst, float(np.max(np.abs(f_hat - out.f))))
        frictions.append(out.f - winch_force_from_sensor(out.F_s_true, robot.sensor.beta_1))
    assert worst < 1e-8
    frictions = np.array(frictions)
    # the friction is there: hysteresis of the order of mu f (table 3.4: about 0.5 N on 6 N)
    assert np.max(np.abs(frictions)) > 0.1
    # and the measured F_s is F_s_true up to quantisation
    lsb = 2 * robot.sensor.range / 2**robot.sensor.bits
    assert np.max(np.abs(out.F_s - out.F_s_true)) <= 0.5 * lsb + 1e-12


def test_ad_conversion_noise_and_sensor_line():
    robot = load_robot("ipanema3")
    s = robot.sensor
    lsb = 2 * s.range / 2**s.bits
    sensor = ForceSensor(s, robot.m, np.random.default_rng(0), noise_std=0.0)
    F = np.linspace(-100.0, 3000.0, robot.m)
    reading = sensor.read(F)
    np.testing.assert_allclose(reading / lsb, np.rint(reading / lsb), atol=1e-9)   # whole codes
    assert np.max(np.abs(reading - F)) <= lsb / 2
    assert sensor.read(np.full(robot.m, 1e6))[0] == pytest.approx(s.range - lsb)   # saturates
    noisy = ForceSensor(s, robot.m, np.random.default_rng(1))
    samples = np.array([noisy.read(np.full(robot.m, 500.0)) for _ in range(4000)])
    assert samples.std() == pytest.approx(np.hypot(s.noise_std, lsb / np.sqrt(12)), rel=0.05)
    # a true line off the calibration (3.29): the reading is off by the same line
    off = ForceSensor(s, robot.m, np.random.default_rng(0), gamma_1=np.full(robot.m, 1.02),
                      gamma_0=np.full(robot.m, 5.0), noise_std=0.0)
    expected = s.gamma_1 * (F / 1.02 + 5.0 - s.gamma_0)
    assert np.max(np.abs(off.read(F) - expected)) <= lsb / 2 + 1e-9


def test_encoder_counts():
    robot = load_robot("ipanema3")
    enc = Encoder.from_drive(robot.drive, 2**20)
    assert enc.resolution == pytest.approx(2 * np.pi * 0.05 / (12 * 2**20))
    theta = np.linspace(1.0, 2.0, 8)
    assert np.max(np.abs(enc.read(theta) - theta)) <= enc.resolution / 2
    assert Encoder.from_drive(robot.drive, 0).read(theta) is not theta


def _run(seed, n=400):
    sim, theta0 = _sim("ipanema3", seed=seed)
    t = sim.config.period * np.arange(n)
    stream_theta, stream_F = [], []
    for k in range(n):
        theta_d = theta0 + 0.003 * np.sin(2 * np.pi * 3 * t[k] + np.arange(8))
        out = sim.step(theta_d)
        stream_theta.append(out.theta)
        stream_F.append(out.F_s)
    sim.close()
    return np.array(stream_theta), np.array(stream_F)


def test_same_seed_same_streams_bit_for_bit():
    theta_a, F_a = _run(7)
    theta_b, F_b = _run(7)
    assert theta_a.tobytes() == theta_b.tobytes()
    assert F_a.tobytes() == F_b.tobytes()
    theta_c, F_c = _run(8)
    assert theta_c.tobytes() == theta_a.tobytes()        # encoders carry no noise
    assert F_c.tobytes() != F_a.tobytes()                # the force noise follows the seed

"""The simulated platform against the model core: statics, stiffness, payload, wrenches, contacts."""
import numpy as np
import pytest

from cdpr_control.model import cable, stiffness
from cdpr_control.model.dynamics import gravity_wrench, mass_matrix
from cdpr_control.model.forward_kinematics import ForwardKinematics
from cdpr_control.model.kinematics import inverse_kinematics, rotation_matrix
from cdpr_control.model.robot import load_robot
from cdpr_sim.contacts import ContactMaterial, Cylinder, Plane, PlatformShape
from cdpr_sim.simulator import SimConfig, Simulator, home_calibration_offset, pretension_lengths
from cdpr_sim.startup import startup_forces, startup_state

# These tests check the simulator against the model equations with the robot file's parameters:
# the perfect-model plant (the default plant differs from the robot file, cdpr_sim.plant).
QUIET = dict(noise_std=0.0, encoder_counts=0, plant="nominal")


def _hold(sim, theta_d, n):
    out = sim.output
    for _ in range(n):
        out = sim.step(theta_d)
    return out


@pytest.mark.parametrize("name, dx", [
    ("ipanema3", [0.4, -0.3, 0.3, 0.03, -0.02, 0.05]),
    ("ipanema3_mini", [0.05, 0.03, -0.04, 0.05, 0.03, -0.04]),
])
def test_holding_ik_minus_the_qp_elongation_settles_at_x(name, dx):
    """theta_d = IK{x} - dq(f_QP): the platform settles at x (0.5 mm, 0.01 deg), true forces = f_QP (1 %)."""
    robot = load_robot(name)
    x = robot.home + np.asarray(dx)
    f_qp = startup_forces(robot, x, 0.4)
    theta_d = pretension_lengths(robot, x, f_qp)
    # start 5 mm / 0.3 deg off, without tension: the platform has to find x itself
    x0 = x + np.array([5e-3, -5e-3, 5e-3, 0.005, -0.005, 0.005])
    sim = Simulator(robot, SimConfig(cable_damping_time=0.004, **QUIET), x0=x0,
                    theta0=inverse_kinematics(robot, x0).q)
    out = _hold(sim, theta_d, 3000)
    assert np.max(np.abs(out.x[:3] - x[:3])) < 0.5e-3
    assert np.max(np.abs(np.rad2deg(out.x[3:] - x[3:]))) < 0.01
    np.testing.assert_allclose(out.f, f_qp, rtol=0.01)
    assert np.max(np.abs(out.xdot)) < 1e-3


def test_startup_state_rests_and_calibrated_encoders_read_the_ik():
    robot = load_robot("ipanema3")
    config = SimConfig(**QUIET)
    x0, theta0, offset = startup_state(robot, robot.home, 0.5, calibrate_home=True, config=config)
    sim = Simulator(robot, config, x0=x0, theta0=theta0, encoder_offset=offset)
    q_home = inverse_kinematics(robot, robot.home).q
    np.testing.assert_allclose(sim.output.theta, q_home, atol=1e-12)     # theta = IK{home} (2.3.2)
    out = _hold(sim, sim.output.theta, 500)                               # hold the encoder values
    assert np.max(np.abs(out.x - robot.home)) < 1e-6
    np.testing.assert_allclose(out.f, startup_forces(robot, robot.home, 0.5), rtol=1e-5)
    np.testing.assert_allclose(offset, home_calibration_offset(robot, out.f), rtol=1e-4)


@pytest.mark.parametrize("name", ["ipanema3", "ipanema3_mini"])
def test_z_eigenfrequency_of_a_step_response_matches_48(name):
    """Step in the vertical force: the oscillation frequency is sqrt(K_x,zz / m) / 2 pi (4.8)."""
    robot = load_robot(name)
    x = robot.home.copy()
    f = startup_forces(robot, x, 0.5)
    theta = pretension_lengths(robot, x, f)
    ik = inverse_kinematics(robot, x)
    K_x = stiffness.operational_stiffness(ik, f, cable.tangent_stiffness(robot, f, cable.total_free_length(robot, ik.q)))
    f_model = stiffness.eigenfrequencies(K_x, mass_matrix(robot, x))[2]
    sim = Simulator(robot, SimConfig(cable_damping_time=0.0005, **QUIET), x0=x, theta0=theta)
    sim.set_external_wrench([0, 0, -0.02 * robot.platform.mass * 9.81, 0, 0, 0])   # the step
    z = np.array([sim.step(theta).x[2] for _ in range(2000)])
    z -= z.mean()
    crossings = np.nonzero(np.signbit(z[1:]) != np.signbit(z[:-1]))[0]
    # sub-sample crossing times by linear interpolation
    t = crossings + z[crossings] / (z[crossings] - z[crossings + 1])
    f_sim = 1.0 / (2.0 * np.mean(np.diff(t)) * sim.config.period)
    assert f_sim == pytest.approx(f_model, rel=0.05)


@pytest.mark.parametrize("name, tau", [("ipanema3", 0.02), ("ipanema3_mini", 0.004)])
def test_payload_equilibrium_is_the_operational_space_fk(name, tau):
    """After a payload change the platform rests where (2.36)-(2.38) of the model core puts it."""
    robot = load_robot(name)
    x = robot.home.copy()
    theta = pretension_lengths(robot, x, startup_forces(robot, x, 0.5))
    sim = Simulator(robot, SimConfig(cable_damping_time=tau, **QUIET), x0=x, theta0=theta)
    payload = (0.6 * robot.platform.mass, (0.01, 0.02, -0.05))
    assert sim.set_payload(*payload) == pytest.approx(1.6 * robot.platform.mass)
    out = _hold(sim, theta, 3000)
    fk = ForwardKinematics(robot.with_payload(*payload)).operational_space(theta, x)
    assert fk.converged
    assert np.max(np.abs(out.x[:3] - fk.x[:3])) < 1e-5
    assert np.max(np.abs(out.x[3:] - fk.x[3:])) < 1e-5
    assert out.x[2] < x[2] - 1e-4                                          # it did sag
    sim.set_payload(0.0)                                                  # removing it: back up
    out = _hold(sim, theta, 3000)
    assert np.max(np.abs(out.x - x)) < 1e-6


def test_external_wrench_equilibrium_and_pulse_shapes():
    robot = load_robot("ipanema3_mini")
    x = robot.home.copy()
    theta = pretension_lengths(robot, x, startup_forces(robot, x, 0.5))
    sim = Simulator(robot, SimConfig(cable_damping_time=0.005, **QUIET), x0=x, theta0=theta)
    w_ext = np.array([2.0, -1.0, 0.5, 0.02, 0.01, -0.03])
    sim.set_external_wrench(w_ext)
    out = _hold(sim, theta, 2000)
    fk = ForwardKinematics(robot).operational_space(theta, x, w=gravity_wrench(robot, x) + w_ext)
    # w is fixed at x in the FK; the moment of the weight turns with the platform: a small difference
    assert np.max(np.abs(out.x[:3] - fk.x[:3])) < 2e-5
    np.testing.assert_array_equal(out.w_ext, w_ext)
    sim.set_external_wrench(np.zeros(6))
    # a half-sine pulse of 50 ms at a point off the origin: torque = point x force
    pulse = sim.apply_pulse([0.0, 3.0, 0.0, 0.0, 0.0, 0.0], point=(0.1, 0.0, 0.0), shape="half_sine", duration=0.05)
    seen = [sim.step(theta).w_ext.copy() for _ in range(80)]
    peak = max(seen, key=lambda w: w[1])
    assert peak[1] == pytest.approx(3.0, rel=1e-3)
    R = np.eye(3)
    assert peak[5] == pytest.approx(np.cross(R @ np.array(pulse.point), [0, peak[1], 0])[2], rel=0.02)
    assert np.all(seen[-1] == 0.0)                                         # over after 50 ms


def test_floor_contact_pushes_back_with_its_stiffness():
    robot = load_robot("ipanema3_mini")
    x = robot.home.copy()
    theta = pretension_lengths(robot, x, startup_forces(robot, x, 0.5))
    tip = np.array([0.0, 0.0, -0.1])
    radius = 0.01
    k = 2e4
    floor = Plane.floor(x[2] + tip[2] - radius - 2e-4, ContactMaterial(stiffness=k, damping=200.0, friction=0.3))
    sim = Simulator(robot, SimConfig(cable_damping_time=0.005, platform_shape=PlatformShape("sphere", radius, tuple(tip)),
                                     obstacles=(floor,), **QUIET), x0=x, theta0=theta)
    assert _hold(sim, theta, 200).w_contact[2] == 0.0                       # 0.2 mm above the floor
    sim.set_external_wrench([0, 0, -20.0, 0, 0, 0])                          # press it down
    out = _hold(sim, theta, 2000)
    penetration = floor.point[2] - ((out.x[:3] + rotation_matrix(out.x[3:]) @ tip)[2] - radius)
    assert penetration > 0.0
    # pybullet lets the bodies sink 10 um (its contact slop) before the spring acts
    assert out.w_contact[2] == pytest.approx(k * (penetration - 1e-5), rel=0.01)
    # force balance on the platform at rest: cables + weight + external + contact = 0
    ik = inverse_kinematics(robot, out.x)
    total = ik.AT @ out.f + gravity_wrench(robot, out.x) + out.w_ext + out.w_contact
    assert np.max(np.abs(total[:3])) < 0.05


def test_substeps_refine_the_physics_step_and_config_is_validated():
    robot = load_robot("ipanema3_mini")
    x = robot.home.copy()
    f = startup_forces(robot, x, 0.5)
    theta = pretension_lengths(robot, x, f)
    runs = []
    for substeps in (1, 4):
        sim = Simulator(robot, SimConfig(substeps=substeps, **QUIET), x0=x, theta0=theta)
        sim.set_external_wrench([0.5, 0.0, -1.0, 0.0, 0.0, 0.0])
        runs.append(np.array([sim.step(theta).x for _ in range(300)]))
    # the same motion up to the integration error of the coarser step (omega dt = 0.4 at 62 Hz)
    motion = np.max(np.abs(runs[1] - x))
    assert np.max(np.abs(runs[0] - runs[1])) < 0.1 * motion
    with pytest.raises(ValueError, match="exceeds 1 ms"):
        SimConfig(period=2e-3, substeps=1)
    SimConfig(period=2e-3, substeps=2)
    with pytest.raises(ValueError):
        Simulator(robot, SimConfig(), x0=x, theta0=theta[:3])
    with pytest.raises(ValueError):
        Simulator(robot, SimConfig(), x0=x, theta0=theta).step(np.full(robot.m, np.nan))


def test_wall_and_cylinder_push_along_their_normals():

    robot = load_robot("ipanema3_mini")
    x = robot.home.copy()
    theta = pretension_lengths(robot, x, startup_forces(robot, x, 0.5))
    tip, radius = np.array([0.0, 0.0, -0.1]), 0.01
    material = ContactMaterial(stiffness=2e4, damping=200.0, friction=0.0)
    # a wall 0.2 mm beside the tip (normal -x), pushed with +x
    wall = Plane((x[0] + radius + 2e-4, 0.0, 0.0), (-1.0, 0.0, 0.0), material)
    # a barrel lying along y below the tip, its top 0.2 mm under the tip, centre offset in x by 2 cm
    R_c, c_x = 0.3, 0.02
    top = x[2] + tip[2] - radius - 2e-4
    z_c = top - np.sqrt(R_c**2 - c_x**2)
    barrel = Cylinder((x[0] + c_x, 0.0, z_c), (0.0, 1.0, 0.0), R_c, 0.5, material)
    for obstacle, push in ((wall, [15.0, 0, 0]), (barrel, [0, 0, -15.0])):
        sim = Simulator(robot, SimConfig(cable_damping_time=0.005, platform_shape=PlatformShape("sphere", radius, tuple(tip)),
                                         obstacles=(obstacle,), **QUIET), x0=x, theta0=theta)
        sim.set_external_wrench(np.r_[push, 0.0, 0.0, 0.0])
        out = _hold(sim, theta, 1500)
        F = out.w_contact[:3]
        assert np.linalg.norm(F) > 0.5
        centre = out.x[:3] + rotation_matrix(out.x[3:]) @ tip
        if obstacle is wall:
            normal = np.array([-1.0, 0.0, 0.0])
        else:
            d = centre - np.array(barrel.center)
            d[1] = 0.0
            normal = d / np.linalg.norm(d)
        np.testing.assert_allclose(F / np.linalg.norm(F), normal, atol=5e-3)   # pybullet's normals: ~2 mrad

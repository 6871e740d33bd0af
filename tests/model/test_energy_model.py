"""Energy consumption model (4.9)-(4.14) with the IPAnema 3 parameters of table 4.6."""
import math

import numpy as np
import pytest

from cdpr_control.model import energy
from cdpr_control.analysis.energy import (REFERENCE_TRIP, THESIS_REFERENCE_TRIP, hold_motion, program_motion,
                                          summary, trajectory_power)
from cdpr_control.model.friction import pulley_force
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot

IPANEMA3 = load_robot("ipanema3")


def test_pulley_4_9_by_hand():
    # one pulley, 90 deg wrap: k = sqrt(2); F_0 = (1000 (2 - 0.01 k) - 2 * 41.71 * 0.5) / (2 + 0.01 k)
    F = energy.pulley_force_before(1000.0, 0.5, 0.010, 41.71, math.pi / 2)
    assert F == pytest.approx(965.24859, rel=1e-7)
    # at rest the pulley passes the force unchanged
    assert energy.pulley_force_before(1000.0, 0.0, 0.010, 41.71, math.pi / 2) == 1000.0


@pytest.mark.parametrize("thetadot", [-1.2, -0.01, 0.01, 0.8])
def test_drum_force_inverts_the_forward_pulley_series(thetadot):
    """(4.9) over every pulley is the inverse of (3.35) from the drum to the platform."""
    r = IPANEMA3
    ik = inverse_kinematics(r, [0.5, -0.3, 1.0, 0.0, 0.0, 0.0])
    f = np.linspace(300.0, 2500.0, r.m)
    v = np.full(r.m, thetadot)
    f_w = energy.drum_force(r, f, v, ik.beta)
    e, fr = r.energy, r.friction
    F = f_w.copy()
    for i in range(r.m):                 # forward: inner pulleys, then the swivelling one
        for _ in range(fr.n_pulleys[i] - 2):
            F[i] = pulley_force(F[i], v[i], e.pulley_mu[i], e.pulley_F_pv[i], fr.beta_inner)
        F[i] = pulley_force(F[i], v[i], e.pulley_mu[i], e.pulley_F_pv[i], ik.beta[i])
    np.testing.assert_allclose(F, f, rtol=1e-12)
    # paying out the platform pulls the cable over the pulleys: the drum sees less (and vice versa)
    assert np.all(np.sign(f - f_w) == np.sign(thetadot))


def test_winch_4_10_4_11_by_hand():
    r = IPANEMA3
    assert energy.motor_speed(r, 0.4338) == pytest.approx(100.0)
    # f_w = 1000 N, alphadot = 100 rad/s, alphaddot = 50 rad/s^2:
    # Coulomb r_w f_w mu_w = 0.004338 * 1000 * 0.3434 = 1.48967 N m,
    # Stribeck 1.48967 + (1.374 - 1.48967) e^(-100/608.6) = 1.391526 N m, viscous 0.0061 * 100 = 0.61 N m
    assert energy.winch_friction_torque(r, 1000.0, 100.0) == pytest.approx(1.391526 + 0.61, rel=1e-6)
    # tau = 4.338 - 0.004562 * 50 - 1.391526 - 0.61
    assert energy.motor_torque(r, 1000.0, 100.0, 50.0) == pytest.approx(2.108374, rel=1e-6)
    # at rest: no friction, the motor holds r_w f_w; the static friction F_s acts only when moving
    assert energy.motor_torque(r, 1000.0, 0.0, 0.0) == pytest.approx(4.338)
    assert energy.winch_friction_torque(r, 0.0, 1e-9) == pytest.approx(1.374, rel=1e-6)


def test_servo_4_12_by_hand():
    r = IPANEMA3
    tau, alphadot = 2.108374, 100.0       # generator: the cable drives the motor with 210.84 W
    amplifier, motor = energy.servo_losses(r, tau, alphadot)
    assert amplifier == pytest.approx(210.8374 * (1.0 - 0.939), rel=1e-6)
    # copper 3 (2.108374 / 2.05)^2 1.532 = 4.86135, re-magnetisation 4.89, eddy 2.74
    assert motor == pytest.approx(4.86135 + 4.89 + 2.74, rel=1e-5)
    assert energy.dc_power(r, tau, alphadot) == pytest.approx(-210.8374 + amplifier + motor)
    # motor operation (hauling in): the amplifier draws the shaft power divided by c_m
    amplifier, _ = energy.servo_losses(r, tau, -alphadot)
    assert amplifier == pytest.approx(210.8374 * (1.0 / 0.939 - 1.0), rel=1e-6)


def test_cabinet_4_13_4_14_by_hand():
    r = IPANEMA3
    P_DC = np.array([1000.0, -400.0, 200.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert energy.dc_link_recovery(P_DC) == pytest.approx(1600.0 - 800.0)
    assert energy.electrical_power(r, P_DC) == pytest.approx(1289.0 + 800.0 / 0.975)
    assert energy.electrical_power(r, -P_DC) == pytest.approx(1289.0 - 800.0 * 0.939)


def test_power_flow_balances_and_losses_are_nonnegative():
    rng = np.random.default_rng(3)
    r = IPANEMA3
    N = 200
    f = rng.uniform(100.0, 3000.0, (N, r.m))
    thetadot = rng.uniform(-1.7, 1.7, (N, r.m))
    thetadot[:20] = 0.0
    thetaddot = rng.uniform(-10.0, 10.0, (N, r.m))
    beta = rng.uniform(0.5, 2.5, (N, r.m))
    flow = energy.power_flow(r, np.arange(N) * 1e-3, f, thetadot, thetaddot, beta)
    total = flow.P_mech + flow.P_pulley + flow.P_winch + flow.P_inertia + flow.P_servo + flow.P_cabinet
    np.testing.assert_allclose(total, flow.P_el, rtol=1e-12, atol=1e-9)
    for name in flow.LOSSES:
        assert np.all(getattr(flow, name) >= -1e-9), name
    assert np.all(flow.P_cabinet >= r.energy.P_0 - 1e-9)


def test_recuperation_on_a_lowering_move():
    """Lowering 100 kg slowly: the drives feed the DC link, the supply feeds back (4.13)-(4.14)."""
    r = IPANEMA3
    down = "G91 G1 F30000 Z-800\nM30\n"          # 0.8 m down at 0.5 m/s
    motion = program_motion(down, [0.0, 0.0, 1.3, 0.0, 0.0, 0.0], 0.5, 2.0, 20.0)
    te = trajectory_power(r, motion, 0.0, payload=100.0)
    assert te.feasible.all()
    cruise = np.linalg.norm(motion.xdot[:, :3], axis=1) > 0.49
    assert cruise.sum() > 500
    P_DC = te.flow.P_DC.sum(axis=1)
    assert np.all(P_DC[cruise] < 0.0)                         # generator operation of the drives
    assert np.all(te.flow.P_el[cruise] < r.energy.P_0)       # fed back to the mains
    assert np.all(te.flow.P_mech[cruise] < 0.0)               # the load does work on the cables
    # the same move upwards costs at least the potential energy m g h more than lowering
    up = program_motion("G91 G1 F30000 Z800\nM30\n", [0.0, 0.0, 0.5, 0.0, 0.0, 0.0], 0.5, 2.0, 20.0)
    lifted = trajectory_power(r, up, 0.0, payload=100.0)
    assert lifted.flow.energy("P_el") - te.flow.energy("P_el") > 125.0 * 9.81 * 0.8


def test_tension_level_raises_standstill_power_as_section_4_4_3_reports():
    """Fig. 4.33: at standstill with the own weight, min tension -20 %, max +30 % against medium."""
    r = IPANEMA3
    hold = hold_motion(r.home, 0.5)
    P = {level: summary(trajectory_power(r, hold, level).flow)["P_el_mean_W"] for level in (0.0, 0.5, 1.0)}
    assert P[0.0] < P[0.5] < P[1.0]
    assert -0.35 < P[0.0] / P[0.5] - 1.0 < -0.10
    assert 0.15 < P[1.0] / P[0.5] - 1.0 < 0.50


def test_reference_trip_of_fig_4_34_is_feasible_and_returns_to_its_height():
    r = IPANEMA3
    s = REFERENCE_TRIP
    motion = program_motion(s.program, s.start, s.velocity, s.acceleration, s.jerk)
    np.testing.assert_allclose(motion.x[-1, :3] - motion.x[0, :3], [0.0, 2.4, 0.0], atol=1e-6)
    assert np.max(np.linalg.norm(motion.xdot[:, :3], axis=1)) == pytest.approx(1.5, rel=1e-3)
    assert np.max(np.linalg.norm(motion.xddot[:, :3], axis=1)) <= 5.0 * (1 + 1e-3)
    te = trajectory_power(r, motion, 0.0, s.payload)
    assert te.feasible.all()
    E = te.flow.energies()
    assert abs(E["E_mech"]) < 0.01 * E["E_el"]     # lifted and lowered by the same height
    # beside the thesis' model figures (section 4.4.3): 4.12 Wh, peak about 8 kW (docs/analysis.md)
    s = summary(te.flow)
    assert s["E_el_Wh"] == pytest.approx(THESIS_REFERENCE_TRIP["energy_Wh"], rel=0.25)
    assert s["P_el_peak_W"] == pytest.approx(THESIS_REFERENCE_TRIP["peak_power_W"], rel=0.25)


def test_winch_efficiency_4_15_reaches_85_percent_at_high_forces():
    """Fig. 4.32: up to about 85 % at high forces; paying out light loads the friction exceeds the
    cable power, the motor must drive and eta_w is undefined."""
    r = IPANEMA3
    f = np.linspace(100.0, 3000.0, 30)[:, None]
    v = np.linspace(-1.7, 1.7, 35)[None, :]
    eta = energy.winch_efficiency(r, f, v)
    assert 0.8 < np.nanmax(eta) < 0.92
    assert np.all(eta[np.isfinite(eta)] < 1.0)
    assert np.isnan(energy.winch_efficiency(r, 100.0, 0.3))              # generator, light load
    assert np.all(np.isfinite(energy.winch_efficiency(r, f[:, 0], -0.5)))  # motor: always defined
    # by hand, motor operation: f_w = 3000 N hauled in at 0.3 m/s: eta = P_w / P_s
    alphadot = -0.3 / 0.004338
    tau = energy.motor_torque(r, 3000.0, alphadot, 0.0)
    assert energy.winch_efficiency(r, 3000.0, -0.3) == pytest.approx(3000.0 * 0.3 / (tau * -alphadot))


def _robot_file(tmp_path, edit):
    import yaml

    from cdpr_control.model.robot import robot_path

    data = yaml.safe_load(robot_path("ipanema3").read_text())
    edit(data)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_energy_section_is_validated_and_optional(tmp_path):
    from cdpr_control.model.robot import RobotFileError

    def efficiency_above_one(d):
        d["energy"]["c_m"] = 1.2

    def negative_inertia(d):
        d["energy"]["J_w"] = -0.1

    def short_pulley_list(d):
        d["energy"]["pulley_mu"] = [0.01, 0.01]

    for edit, key in ((efficiency_above_one, "energy.c_m"), (negative_inertia, "energy.J_w"),
                      (short_pulley_list, "energy.pulley_mu")):
        with pytest.raises(RobotFileError, match=key.replace(".", r"\.")):
            load_robot(_robot_file(tmp_path, edit))
    robot = load_robot(_robot_file(tmp_path, lambda d: d.pop("energy")))
    assert robot.energy is None
    with pytest.raises(ValueError, match="no 'energy' section"):
        energy.motor_speed(robot, 1.0)

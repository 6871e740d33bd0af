"""The simulator's compiled period (cdpr_sim.period, Simulator.fused) gives the numbers of its readable
path bit for bit: every SimOutput field of every period, and the state the next period starts from,
on both robots, with and without friction, settlement, external wrenches and pulses, payloads
(an offset centre of gravity), substeps, pulley IK refreshes and contact."""
import numpy as np
import pytest

from cdpr_control.model.kinematics import inverse_kinematics, rotation_matrix
from cdpr_control.model.robot import load_robot
from cdpr_sim.cables import CableModel
from cdpr_sim.contacts import ContactMaterial, Plane, default_tool
from cdpr_sim.period import kardan_into
from cdpr_sim.platform import kardan_angles
from cdpr_sim.simulator import SimConfig, Simulator, SimOutput
from cdpr_sim.startup import startup_state

FIELDS = SimOutput.__slots__


SCENARIOS = {
    # the demo's simulator (closed_loop.yaml): mismatched plant, friction, settlement, noise, encoders
    "mini_demo": ("ipanema3_mini", 0.0, {}, 2000, 0.0, {}),
    "mini_wrench_pulse": ("ipanema3_mini", 0.0, {}, 2500, 2e-3, {
        300: lambda s: s.set_external_wrench([3.0, -2.0, 5.0, 0.1, -0.2, 0.05]),
        900: lambda s: s.apply_pulse([0.0, 0.0, -20.0, 0.0, 0.0, 0.0], (0.01, 0.0, 0.0), "half_sine", 0.2),
        1600: lambda s: s.set_external_wrench(np.zeros(6)),
        1700: lambda s: s.apply_pulse([5.0, 0.0, 0.0, 0.0, 0.0, 0.0], shape="step", duration=0.1)}),
    "mini_nominal_no_friction": ("ipanema3_mini", 0.5, {"friction": False, "plant": "nominal"}, 1500, 5e-3, {}),
    "mini_substeps_payload": ("ipanema3_mini", 0.3, {"substeps": 2, "seed": 3}, 1200, 3e-3, {
        200: lambda s: s.set_payload(0.5, (0.01, 0.0, -0.02)),
        800: lambda s: s.set_payload(0.0)}),
    "ipanema3_moving": ("ipanema3", 0.5, {}, 2500, 2e-2, {
        700: lambda s: s.set_external_wrench([30.0, -20.0, 50.0, 1.0, -2.0, 0.5]),
        1800: lambda s: s.apply_pulse([50.0, 0.0, -200.0, 0.0, 0.0, 0.0], (0.1, 0.0, 0.0), "step", 0.3)}),
    "ipanema3_no_friction_no_noise": ("ipanema3", 0.5, {"friction": False, "noise_std": 0.0, "encoder_counts": 0},
                                      1500, 1e-2, {}),
}


def build(name, level, config):
    robot = load_robot(name)
    config = {"noise_std": robot.sensor.noise_std, **config}
    if config.pop("floor", False):
        radius, centre = default_tool(robot.b)
        height = float(robot.home[2] + centre[2] - radius - 0.002)
        config["obstacles"] = (Plane.floor(height, ContactMaterial(2e4, 200.0, 0.3)),)
    cfg = SimConfig(**config)
    x0, theta0, offset = startup_state(robot, robot.home, level, True, cfg)
    return Simulator(robot, cfg, x0=x0, theta0=theta0, encoder_offset=offset)


def same(a, b) -> bool:
    """Bit for bit (np.array_equal would take -0.0 for 0.0)."""
    if isinstance(a, float):
        return np.float64(a).tobytes() == np.float64(b).tobytes()
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def run_both(name, level, config, n, amplitude, events):
    fused, readable = build(name, level, config), build(name, level, config)
    readable.fused = False
    refreshes = []
    refresh = fused.cables.refresh
    fused.cables.refresh = lambda x: (refreshes.append(fused.steps), refresh(x))
    theta = fused.output.theta.copy()
    phase = np.arange(fused.m)
    for k in range(n):
        for sim in (fused, readable):
            if k in events:
                events[k](sim)
        theta_d = theta + amplitude * np.sin(2.0 * np.pi * 0.7e-3 * k + phase)
        a, b = fused.step(theta_d), readable.step(theta_d)
        for field in FIELDS:
            assert same(getattr(a, field), getattr(b, field)), (k, field)
    for attr in ("overloads", "slackened", "moved"):
        assert same(float(getattr(fused.cables, attr)), float(getattr(readable.cables, attr))), attr
    assert same(fused.settlement.s, readable.settlement.s)
    assert same(fused.friction.dahl.state, readable.friction.dahl.state)
    assert same(fused.drives.theta, readable.drives.theta) and same(fused.drives.thetadot, readable.drives.thetadot)
    fused.close()
    readable.close()
    return refreshes


@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_fused_period_is_the_readable_path(scenario):
    refreshes = run_both(*SCENARIOS[scenario])
    if scenario == "ipanema3_moving":
        assert refreshes, "the scenario should move the anchors beyond the refresh distance"


def test_fused_period_in_contact():
    run_both("ipanema3_mini", 0.0, {"floor": True}, 1500, 2e-2, {})


def test_fused_period_refuses_what_the_readable_path_refuses():
    sim = build("ipanema3_mini", 0.0, {})
    before = sim.output
    for bad in (np.full(sim.m, np.nan), np.r_[np.zeros(sim.m - 1), np.inf]):
        with pytest.raises(ValueError, match="finite numbers"):
            sim.step(bad)
    assert sim.output is before and sim.steps == 0
    with pytest.raises(ValueError):          # another length: the readable path's broadcasting error
        sim.step(np.zeros(sim.m + 1))
    sim.close()


def test_compiled_kardan_angles_are_platform_kardan_angles():
    rng = np.random.default_rng(5)
    x = np.empty(6)
    angles = np.concatenate([rng.uniform(-np.pi, np.pi, (20000, 3)), rng.normal(0.0, 1e-3, (20000, 3)),
                             [[0.0, np.pi / 2, 0.0], [0.0, -np.pi / 2, 0.3], [-0.0, 0.0, -0.0]]])
    for a in angles:
        R = rotation_matrix(a)
        kardan_into(R, x)
        assert same(x[3:], kardan_angles(R))


def test_force_table_search_from_the_last_interval_is_the_binary_search():
    robot = load_robot("ipanema3_mini")
    hinted, fresh = (CableModel(robot, 0.002) for _ in range(2))
    for model in (hinted, fresh):
        model.refresh(robot.home)
    rng = np.random.default_rng(11)
    q = inverse_kinematics(robot, robot.home).q
    theta = q - 1e-3
    for k in range(3000):           # slow drifts, jumps, slack cables and strains beyond the table
        theta = theta + rng.normal(0.0, 2e-6, 8) if k % 300 else q - rng.uniform(-2e-3, 3e-2, 8)
        r = robot.home[:3] + rng.normal(0.0, 1e-4, 3)
        R = rotation_matrix(robot.home[3:] + rng.normal(0.0, 1e-3, 3))
        v, omega, thetadot = rng.normal(0.0, 0.01, 3), rng.normal(0.0, 0.01, 3), rng.normal(0.0, 0.01, 8)
        fresh._hint[:] = 0
        a, b = hinted.wrench(r, R, v, omega, theta, thetadot), fresh.wrench(r, R, v, omega, theta, thetadot)
        for x, y in zip(a, b):
            assert same(x, y), k
        assert same(hinted.linearisation()[1], fresh.linearisation()[1])
    assert hinted.overloads == fresh.overloads > 0

"""A push and a payload beyond the limits (issue 18, item 5): the simulator stays stable, the loop
holds, and an impossible payload is named.

A 1000 N pulse of 0.5 s on the IPAnema 3 Mini (1 kg platform, 40 N cables) is 100 times its
weight: the cables go slack on one side and far beyond their rated force on the other. The
physics must stay physical (no energy from nowhere, bounded forces, no NaN) and the motion must
decay once the push is over; slack cables that snap taut must not add energy. With the force
controllers closed around it, the commands stay finite and within the drives' rate limit.
A payload far beyond the robot (100 kg on the Mini) is refused by the program check and simulated
with a warning. Default (mismatched) plant throughout.
"""
import numpy as np
import pytest

from cdpr_control.force_distribution import wrench_feasible
from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.program import GCodeError
from cdpr_control.motion.program_check import check_program, payload_capacity
from cdpr_control.model.robot import load_robot
from cdpr_control.model.workspace import static_problem, with_platform_mass
from cdpr_tools.cli import main as cdpr
from cdpr_sim import closed_loop
from cdpr_sim.simulator import SimConfig, Simulator
from cdpr_sim.startup import startup_state

PUSH = 1000.0           # N
PUSH_START, PUSH_TIME = 0.1, 0.5       # s


def total_energy(sim) -> float:
    """Kinetic + gravitational + elastic energy [J] of the platform and its cables at sim's state."""
    body, robot = sim._body, sim.robot
    r, R, v, omega = body.state()
    rho = R @ body.c
    v_c = v + np.cross(omega, rho)
    J = R @ body.inertia @ R.T
    kinetic = 0.5 * body.mass * v_c @ v_c + 0.5 * omega @ J @ omega
    gravity = -body.mass * np.dot(robot.gravity, r + rho)
    return kinetic + gravity + sim.cables.potential_energy(r, R, sim.drives.theta + sim.settlement.s)


def _mini_at_rest(config=SimConfig()):
    robot = load_robot("ipanema3_mini")
    x0, theta0, offset = startup_state(robot, robot.home, 0.0, calibrate_home=True, config=config)
    return robot, Simulator(robot, config, x0=x0, theta0=theta0, encoder_offset=offset)


def test_a_1000_N_push_decays_with_a_held_command():
    """IK-only / held command: the winches keep their lengths, only the plant acts."""
    robot, sim = _mini_at_rest()
    with sim:
        command = sim.output.theta.copy()
        f, x, energy = [], [], []
        for k in range(2600):                               # 2.6 s: 2 s after the push
            if k == round(PUSH_START / sim.config.period):
                sim.apply_pulse([PUSH, 0, 0, 0, 0, 0], shape="rectangle", duration=PUSH_TIME)
            out = sim.step(command)
            f.append(out.f)
            x.append(out.x)
            energy.append(total_energy(sim))
    f, x, energy, t = np.array(f), np.array(x), np.array(energy), sim.config.period * np.arange(1, 2601)
    assert np.all(np.isfinite(f)) and np.all(np.isfinite(x))
    # a step of 1000 N on stiff cables: at most a few times the push (it was 45 kN)
    assert f.max() < 5.0 * PUSH
    after = t >= PUSH_START + PUSH_TIME + 2 * sim.config.period
    e_end = energy[np.argmax(after)]
    # once the push is over nothing adds energy: damping and settlement only take it away
    assert np.max(energy[after]) < e_end + 1e-3
    late = t > t[-1] - 0.5
    assert np.max(energy[late]) < e_end - 0.5 * (e_end - energy[-1]) + 1e-3     # it decays, not just holds
    # within 1.5 s the platform is at rest again (it swung by tens of millimetres before)
    assert np.ptp(x[late, :3], axis=0).max() < 1e-4
    assert np.ptp(x[late, 3:], axis=0).max() < 1e-3
    assert np.all(f[late] < robot.cable.f_max)


def test_slack_cables_snapping_taut_add_no_energy():
    """The platform is thrown at 3 m/s with every cable just slack: they snap taut at far beyond
    their rated force and the energy must not grow (an explicit step gained energy here)."""
    robot, sim = _mini_at_rest()
    with sim:
        theta = sim.drives.theta + 2e-4                       # every cable 0.2 mm slack
        sim.reset(robot.home, theta, xdot0=[3.0, -1.0, 1.0, 0.0, 0.0, 0.0], encoder_offset=sim.encoder_offset)
        command = sim.output.theta.copy()
        e0 = total_energy(sim)
        energy, f = [], []
        for _ in range(1000):
            out = sim.step(command)
            energy.append(total_energy(sim))
            f.append(out.f)
    energy, f = np.array(energy), np.array(f)
    assert np.all(np.isfinite(f))
    assert np.max(f) > 4.0 * np.max(robot.cable.f_max)                # the transitions are violent
    assert np.max(energy) < e0 + 1e-3
    assert energy[-1] < 0.2 * e0 + 0.8 * energy.min()      # and the cables' damping takes most of it


def test_force_control_holds_through_a_1000_N_push():
    """With the force controllers (closed_loop.run, the robot's parameter file): finite commands
    within the rate limit throughout, cable forces back within the limits after the push and
    the platform back near its set-point."""
    robot = load_robot("ipanema3_mini")
    period = SimConfig().period

    def push(k, loop, sim):
        if k == round(PUSH_START / period):
            sim.apply_pulse([PUSH, 0, 0, 0, 0, 0], shape="rectangle", duration=PUSH_TIME)

    run = closed_loop.run(robot, closed_loop.hold(robot.home), 2.1, before_step=push)
    assert np.all(np.isfinite(run.theta_d)) and np.all(np.isfinite(run.f))
    step = np.abs(np.diff(run.theta_d, axis=0)).max()
    assert step <= robot.drive.v_max * period * (1 + 1e-9)
    assert run.f.max() < 5.0 * PUSH
    late = run.t > run.t[-1] - 0.5
    c = robot.cable
    assert np.all(run.f[late] > 0.5 * c.f_min) and np.all(run.f[late] < c.f_max)
    assert np.abs(run.x[late, :3] - robot.home[:3]).max() < 5e-3
    assert np.ptp(run.x[late, :3], axis=0).max() < 1e-3                 # settling, not swinging


def test_a_payload_beyond_the_robot_is_simulated_with_a_warning():
    """The simulator may overload itself (a fault to test against) but says why: 100 kg on the
    Mini (40 N cables) is held by no cable forces within the limits; 0.5 kg is."""
    robot, sim = _mini_at_rest()
    with sim:
        assert sim.set_payload(0.5) == 1.5 and sim.payload_warning is None
        assert sim.set_payload(100.0) == pytest.approx(101.0)
        assert "beyond what the robot can hold" in sim.payload_warning
        assert "[5, 40] N" in sim.payload_warning and "simulating the overload" in sim.payload_warning
        capacity = float(sim.payload_warning.split("capacity there ")[1].split(" kg")[0])
        assert 0.5 < capacity < 100.0
        sim.set_payload(0.0)
        assert sim.payload_warning is None


def test_program_check_refuses_a_payload_beyond_the_capacity(capsys):
    """A controller-side payload that no cable forces hold at home is refused with the reason, in
    check_program (the interpreter's goals) and in `cdpr program check --payload`."""
    robot = load_robot("ipanema3_mini")
    capacity = payload_capacity(robot)
    # at the capacity the platform's weight needs some cable at f_max, just beyond it none suffices
    AT, w = static_problem(with_platform_mass(robot, robot.platform.mass + capacity), robot.home[None])
    assert wrench_feasible(AT, w, robot.cable.f_min, robot.cable.f_max)[0]
    AT, w = static_problem(with_platform_mass(robot, robot.platform.mass + 1.01 * capacity), robot.home[None])
    assert not wrench_feasible(AT, w, robot.cable.f_min, robot.cable.f_max)[0]
    program = parse_gcode("G90 G1 X0 F6000\nG1 X10", start_pose=robot.home)
    assert check_program(program, robot, payload=0.5 * capacity) > 0
    with pytest.raises(GCodeError) as err:
        check_program(program, robot, payload=100.0)
    d = err.value.diagnostics[0]
    assert d.line == 1 and "100 kg is beyond what IPAnema 3 Mini can hold" in d.message
    assert f"capacity there is {capacity:.3g} kg" in d.message
    assert cdpr(["program", "check", "--robot", "ipanema3_mini", "--payload", "100", "rectangle"]) == 1
    assert "beyond what IPAnema 3 Mini can hold" in capsys.readouterr().out

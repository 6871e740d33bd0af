"""Acceptance: identified friction parameters reduce the wrench hysteresis (section 3.7.4) by >= 70 %.

The chain a user runs: record the section 3.7.2 identification run into a bag, ``cdpr identify
friction`` it into the compensation node's parameter file (3.45), load that file into the
compensation stage (3.44), then measure the wrench w = -A^T(x) f on a crossing run of the IPAnema 3
Mini: IK-only control (theta_d = IK{x_d}, encoders calibrated at home under the start-up tension,
section 2.3.2) moves the platform through the home pose along z, x_d,z = home_z + A sin(2 pi f t),
as in the measurement of Fig. 3.19.

Hysteresis width (Table 3.5, Fig. 3.19: the horizontal spread of the closed w_z(z) curve, 7.6 N
without and 0.8 N with compensation): the error of the measured force e_z = w_z - w_z,true is
binned by the true platform height z over the inner part of the stroke (the turning points, where
both branches meet and the direction is ill defined, are left out); the width is the largest
|mean over the upward branch - mean over the downward branch| over the bins. Subtracting the truth
removes the platform's own dynamics (for a sine, m (zddot + g) is the same on both branches) and the
sensor noise averages out in the bins, so what remains is the friction seen by the winch sensors.
"""
import numpy as np
import pytest
import yaml

from cdpr_control.model.friction import winch_force_from_sensor
from cdpr_control.control.friction_compensation import FrictionCompensation, FrictionCompensationParams
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot

ROBOT = "ipanema3_mini"
DT = 1e-3
AMPLITUDE, FREQUENCY, CYCLES = 0.02, 0.5, 3        # m, Hz, evaluated cycles (one more fades in)
INNER = 0.75                                        # evaluated part of the stroke, |z - z_home| / A
BINS = 12
# a few seconds of the section 3.7.2 trajectory, as tests/tools/test_identify.py


def crossing_trajectory(home) -> tuple[np.ndarray, np.ndarray]:
    """x_d (N, 6) crossing home along z: one fade-in cycle, then CYCLES full sine cycles; and the mask
    of the evaluated samples (after the fade-in)."""
    period = 1.0 / FREQUENCY
    t = np.arange(int(round((CYCLES + 1) * period / DT)) + 1) * DT
    fade = np.clip(t / period, 0.0, 1.0)
    fade = fade**3 * (10.0 - 15.0 * fade + 6.0 * fade**2)   # smooth start (quintic smoothstep)
    x_d = np.repeat(np.asarray(home, dtype=float)[None], len(t), axis=0)
    x_d[:, 2] += AMPLITUDE * fade * np.sin(2.0 * np.pi * FREQUENCY * t)
    return x_d, t >= period


def simulate_crossing(robot, seed: int = 5) -> dict:
    """IK-only crossing run; per period what the loop measures and the ground truth."""
    from cdpr_sim.simulator import SimConfig, Simulator
    from cdpr_sim.startup import startup_state

    x_d, evaluated = crossing_trajectory(robot.home)
    config = SimConfig(seed=seed, friction=True)               # the default, mismatched plant
    x0, theta0, offset = startup_state(robot, robot.home, level=0.5, calibrate_home=True, config=config)
    keys = ("F_s", "theta", "thetadot", "x", "f")
    rec = {k: [] for k in keys}
    with Simulator(robot, config, x0=x0, theta0=theta0, encoder_offset=offset) as sim:
        for xk in x_d:
            out = sim.step(inverse_kinematics(robot, xk).q)   # encoders read IK{home} at home
            for k in keys:
                rec[k].append(np.array(getattr(out, k), dtype=float))
    rec = {k: np.array(v) for k, v in rec.items()}
    rec["x_d"], rec["evaluated"] = x_d, evaluated
    return rec


def identified_parameters(identified) -> FrictionCompensationParams:
    """The file `cdpr identify friction -o` wrote from the identification run (conftest.py's
    ``identified_friction``, shared with tests/tools/test_identify.py), read as the node does."""
    assert identified.code == 0
    p = yaml.safe_load(identified.params.read_text())["friction_compensation"]["ros__parameters"]
    return FrictionCompensationParams(mu=np.array(p["mu"]), sigma=np.array(p["sigma"]), F_pv=np.array(p["F_pv"]))


def wrench_z(robot, x, f) -> np.ndarray:
    """w_z = -(A^T(x) f)_z per sample: the force the cables' measured tension says acts on the platform."""
    AT = inverse_kinematics(robot, x).AT                       # (N, 6, m), vectorised over the poses
    return -np.einsum("nm,nm->n", AT[:, 2, :], f)


def hysteresis_width(z, zdot, e, z_home) -> float:
    """max over z bins of |mean(e | zdot > 0) - mean(e | zdot < 0)| over |z - z_home| <= INNER A."""
    edges = z_home + np.linspace(-INNER * AMPLITUDE, INNER * AMPLITUDE, BINS + 1)
    up, down = zdot > 0, zdot < 0
    widths = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        inside = (z >= lo) & (z < hi)
        assert np.count_nonzero(inside & up) > 20 and np.count_nonzero(inside & down) > 20
        widths.append(abs(e[inside & up].mean() - e[inside & down].mean()))
    return float(max(widths))


@pytest.fixture(scope="module")
def widths(identified_friction):
    robot = load_robot(ROBOT)
    params = identified_parameters(identified_friction)
    run = simulate_crossing(robot)

    f_w = winch_force_from_sensor(run["F_s"], robot.sensor.beta_1)             # (3.40), no compensation
    stage = FrictionCompensation(robot, DT, params)                             # the node's stage (3.44)
    betas = inverse_kinematics(robot, run["x_d"]).beta                          # node: IK of the set-point
    f_comp = np.array([stage.update(F_s, th, thd, b)
                       for F_s, th, thd, b in zip(run["F_s"], run["theta"], run["thetadot"], betas)])

    x = run["x"]
    w_true = wrench_z(robot, x, run["f"])
    keep = run["evaluated"]
    z = x[keep, 2]
    zdot = np.gradient(run["x_d"][:, 2], DT)[keep]                               # branch from the set-point
    result = {name: hysteresis_width(z, zdot, (wrench_z(robot, x, f) - w_true)[keep], robot.home[2])
              for name, f in (("without", f_w), ("with", f_comp))}
    # the true wrench itself, not its error: the crossing run's own hysteresis (dynamics, cable damping)
    result["truth_raw"] = hysteresis_width(z, zdot, w_true[keep], robot.home[2])
    print(f"\nwrench hysteresis width w_z (A = {AMPLITUDE * 1e3:.0f} mm, {FREQUENCY} Hz): "
          f"without compensation {result['without']:.3f} N, with identified compensation {result['with']:.3f} N "
          f"({100 * (1 - result['with'] / result['without']):.1f} % less); true wrench alone "
          f"{result['truth_raw']:.3f} N")
    return result


def test_friction_causes_a_wrench_hysteresis_without_compensation(widths):
    # the uncompensated sensor must show a hysteresis to be reduced, and it must come from the
    # pulleys, not from the run: the true wrench m (zddot + g) is nearly the same on both branches
    assert widths["without"] > 0.5
    assert widths["truth_raw"] < 0.05 * widths["without"]


def test_identified_compensation_reduces_wrench_hysteresis_by_70_percent(widths):
    assert widths["with"] <= 0.3 * widths["without"], widths

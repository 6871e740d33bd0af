"""Friction identification (3.45) finds the plant it was recorded on, for each plant seed.

The identification experiments (cdpr_tools.identify.experiments) used to take ``seed`` as the sensor
noise's seed only and always simulate plant seed 1: a friction run "recorded on seed 2" of the
IPAnema 3 fitted seed 1's pulleys, 22-46 % off seed 2's (docs/validation.md, "Friction
identification after session 10"). Each seed's run here is recorded on that seed's plant
(``plant_seed``) with one noise seed for all, and fitted per cable as ``cdpr identify friction``
does; every cable's mu, sigma, F_pv must be the plant's within the bands of tests/tools/test_identify.py
(3 %, 5 %, 5 %). The run is 9.6 s (SHORT_RUN), against the 17.6 s of the default.
"""
import numpy as np
import pytest

from cdpr_control.kernels.jit import njit
from cdpr_control.model.robot import load_robot
from cdpr_sim.plant import build_plant
from cdpr_tools.bag import BagReader
from cdpr_tools.identify import experiments, friction

SEEDS = (1, 2, 3)
# identified here: seed 2 (plant seed 1 is identified in tests/tools/test_identify.py; one other seed catches
# experiments that ignore plant_seed; seed 3, same path, measured 0.6 / 1.0 / 3.7 %: docs/validation.md)
IDENTIFIED_SEEDS = (2,)
NOISE_SEED = 7            # one noise for every plant: only the plant differs between the runs
# the stop-and-go part of tests/conftest.py's short run, the fast part of the full one (30 mm at
# 0.17-0.5 m/s): with conftest's 10 mm at 0.2-0.4 m/s the lower cables' F_pv came out 9 % off
SHORT_RUN = {"amplitudes": (0.0005, 0.002, 0.005), "pause": 0.05}
BANDS = {"mu": 0.03, "sigma": 0.05, "F_pv": 0.05}


@pytest.fixture(scope="module")
def ipanema3():
    return load_robot("ipanema3")


@pytest.fixture(scope="module", params=IDENTIFIED_SEEDS, ids=lambda s: f"plant_seed_{s}")
def identified(request, ipanema3, tmp_path_factory):
    """(plant seed, identified parameters {name: (m,)}) of the seed's short friction run."""
    seed = request.param
    bag = experiments.record_friction_run(tmp_path_factory.mktemp(f"friction_seed{seed}") / "friction", ipanema3,
                                          seed=NOISE_SEED, plant_seed=seed, **SHORT_RUN)
    data = friction.load_data(BagReader(bag), ipanema3)
    fits = [friction.fit_cable(ipanema3, data, i, jit=njit) for i in range(ipanema3.m)]
    return seed, {name: np.array([getattr(f, name) for f in fits]) for name in BANDS}


def _plant_friction(robot, seed):
    return build_plant(robot, "mismatched", seed).robot.friction


def test_the_seeds_are_told_apart_by_the_bands(ipanema3):
    """The check below can fail: any two seeds' plants differ beyond a band on some cable, and so
    does each plant from the robot file (which a fit that ignored the data would return)."""
    plants = {seed: _plant_friction(ipanema3, seed) for seed in SEEDS}
    candidates = [(f"seed {s}", p) for s, p in plants.items()] + [("robot file", ipanema3.friction)]
    for seed, plant in plants.items():
        for label, other in candidates:
            if label == f"seed {seed}":
                continue
            worst = {name: np.max(np.abs(getattr(other, name) / getattr(plant, name) - 1.0)) for name in BANDS}
            assert any(worst[name] > 2.0 * band for name, band in BANDS.items()), (seed, label, worst)


def test_friction_identified_on_each_plant_seed_is_that_plants(identified, ipanema3):
    seed, p = identified
    plant = _plant_friction(ipanema3, seed)
    for name, band in BANDS.items():
        error = p[name] / getattr(plant, name) - 1.0
        assert np.max(np.abs(error)) < band, (seed, name, np.round(error, 4).tolist())

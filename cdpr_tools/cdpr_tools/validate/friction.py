"""The friction the sweep's guiding and payload cases run with: identified on the case's plant first,
as a user runs the robot (docs/validation.md, "Guiding with identified friction (session 10)",
"Payload after session 15").

Per (robot, plant, seed) the friction identification run is recorded on that plant
(:func:`cdpr_tools.identify.experiments.record_friction_run` with ``plant``, ``plant_seed``) and
fitted by (3.45) (:func:`cdpr_tools.identify.friction.identify`), as ``cdpr identify
record-experiments`` and ``cdpr identify friction -o`` do; the parameter file goes to
``<output>/friction/<robot>_<plant>[_seed<N>].yaml`` and is reused by every later run with the same
output directory. The cases get mu, sigma, F_pv of that file in their friction compensation
(FrictionCompensationParams), the rest of the shipped configuration unchanged.

``shipped``: the robot file's pulley friction (the shipped parameter files set none), which the
mismatched plants miss by 15-37 % on the IPAnema 3 (cdpr_sim.plant).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cdpr_tools.validate import plant_cache

MODES = ("identified", "shipped")
# the families --friction applies to (the payload's estimate (4.4) reads the friction-compensated
# forces: the plant's Coulomb friction off the robot file's by 20 % reads as 0.15-0.7 kg at
# ipanema3 #9 and #25, docs/validation.md "Payload after session 15"); the others run with the robot file's
FAMILIES = ("guiding", "payload")
NAMES = ("mu", "sigma", "F_pv")  # the friction_compensation parameters a fit gives (3.45)


def shipped() -> dict:
    """A case's friction record for the robot file's friction."""
    return {"source": "shipped"}


def parameter_path(outdir, robot_name: str, plant: str, seed: int) -> Path:
    """Where the sweep keeps the friction identified on a plant."""
    return plant_cache.parameter_path(outdir, "friction", robot_name, plant, seed)


def read_parameters(path) -> dict:
    """mu, sigma, F_pv (lists) of a friction_compensation parameter file."""
    import yaml

    values = yaml.safe_load(Path(path).read_text())["friction_compensation"]["ros__parameters"]
    return {k: [float(v) for v in values[k]] for k in NAMES}


def identify_on_plant(robot_name: str, plant: str, seed: int, path: Path, progress=None) -> None:
    """Record the friction run on the plant (sensor noise seed ``seed or 1``), fit (3.45) on every
    cable and write the parameter file to ``path`` (the bag beside it, ``<stem>_run/``)."""
    from cdpr_control.model.robot import load_robot
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify import experiments, friction
    try:                                               # the simulator's compiled kernels, as `cdpr identify` uses
        from cdpr_sim.simulator import compiled
    except ImportError:
        compiled = None

    robot = load_robot(robot_name)
    bag = experiments.record_friction_run(plant_cache.run_directory(path), robot, seed=seed or 1, plant=plant, plant_seed=seed or 1)
    _, fits = friction.identify(BagReader(bag), robot, jit=compiled, progress=progress)
    tmp = path.with_suffix(".yaml.tmp")
    friction.write_parameter_file(fits, tmp)
    os.replace(tmp, path)                              # a reader sees the whole file or none


def identified(outdir, robot_name: str, plant: str, seed: int, progress=None) -> tuple[dict, bool]:
    """The friction identified on (robot, plant, seed) -> (the cases' friction record, reused): the
    parameter file (identified now, under a file lock, if the output directory has none; reused:
    it was there), its values and how far they are from the robot file's (``deviation_percent``:
    worst cable per parameter)."""
    path = parameter_path(outdir, robot_name, plant, seed)
    reused = plant_cache.identified_once(path, lambda p: identify_on_plant(robot_name, plant, seed, p, progress))
    values = read_parameters(path)
    return {"source": "identified", "file": str(path), **values,
            "deviation_percent": deviation_percent(robot_name, values)}, reused


def deviation_percent(robot_name: str, values: dict) -> dict:
    """Per parameter the largest |identified - robot file| / robot file [%] over the cables."""
    from cdpr_control.model.robot import load_robot

    fr = load_robot(robot_name).friction
    return {k: float(100.0 * np.max(np.abs(np.asarray(values[k]) / np.asarray(getattr(fr, k), dtype=float) - 1.0)))
            for k in NAMES}


def loop_params(robot_name: str, record: dict):
    """The shipped loop with the record's friction in its friction compensation (None: shipped)."""
    from cdpr_control.control.params import shipped_configuration

    if record.get("source", "shipped") == "shipped":
        return None
    return with_friction(shipped_configuration(robot_name).loop, record)


def with_friction(loop, record: dict):
    """``loop`` (ControlLoopParams) with the record's friction in its friction compensation
    (unchanged where the record is the robot file's)."""
    from dataclasses import replace

    if record.get("source", "shipped") == "shipped":
        return loop
    return replace(loop, friction=replace(loop.friction, **{k: np.asarray(record[k], dtype=float) for k in NAMES}))


def text(record: dict) -> str:
    """One phrase: which friction a case ran with."""
    if record.get("source", "shipped") == "shipped":
        return "friction of the robot file"
    d = record.get("deviation_percent", {})
    off = " / ".join(f"{d[k]:.3g}" for k in NAMES) if d else "?"
    return f"friction identified on the plant (mu / sigma / F_pv up to {off} % from the robot file's)"

"""The cable settlement the sweep's payload cases run with: identified on the case's plant first, as a
user runs the robot (docs/load_compensation.md, "Identify first, then compensate"; docs/validation.md,
"Payload after session 13"), the way :mod:`.friction` does it for the guiding cases.

Per (robot, plant, seed) the settlement run is recorded on that plant
(:func:`cdpr_tools.identify.experiments.record_settlement_run`: a payload put on at home under IK-only
control, held, taken off, the pose from the simulated tracker) and fitted
(:func:`cdpr_tools.identify.settlement.identify`), as ``cdpr identify settlement -o`` does; the
parameter file goes to ``<output>/settlement/<robot>_<plant>[_seed<N>].yaml`` and is reused by every
later run with the same output directory. The cases get settlement_ratio, settlement_time of that
file and ``settlement_identified: true`` in their load compensation (so the settlement also goes to
the pose estimator, cause A), the rest of the shipped configuration unchanged.

``shipped``: the parameter file's settlement model (the IPAnema 3's assumed 0.15, the Mini's off),
never in the pose estimator.
"""
from __future__ import annotations

import os
from pathlib import Path

from cdpr_tools.validate import plant_cache

MODES = ("identified", "shipped")
NAMES = ("settlement_ratio", "settlement_time")
PAYLOAD_SHARE = 0.4    # the run's payload: this share of the planned static capacity at home (64 kg on the IPAnema 3)


def shipped() -> dict:
    """A case's settlement record for the parameter file's model."""
    return {"source": "shipped"}


def parameter_path(outdir, robot_name: str, plant: str, seed: int) -> Path:
    """Where the sweep keeps the settlement identified on a plant."""
    return plant_cache.parameter_path(outdir, "settlement", robot_name, plant, seed)


def run_payload(robot) -> float:
    """The settlement run's payload [kg] at home: PAYLOAD_SHARE of the shipped distribution's static
    capacity there (cases.planned_capacity)."""
    from cdpr_tools.validate.cases import planned_capacity

    return PAYLOAD_SHARE * planned_capacity(robot, robot.home)


def identify_on_plant(robot_name: str, plant: str, seed: int, path: Path) -> None:
    """Record the settlement run on the plant (sensor noise seed ``seed or 1``), fit the model and
    write the load_compensation parameter file to ``path`` (the bag beside it, ``<stem>_run/``)."""
    import yaml

    from cdpr_control.model.robot import load_robot
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify import experiments, settlement

    robot = load_robot(robot_name)
    payload = run_payload(robot)
    bag = experiments.record_settlement_run(plant_cache.run_directory(path), robot, payload=payload, hold=6.0, seed=seed or 1,
                                            plant=plant, plant_seed=seed or 1)
    fit = settlement.identify(BagReader(bag), robot)
    tmp = path.with_suffix(".yaml.tmp")
    tmp.write_text(yaml.safe_dump({"load_compensation": {"ros__parameters": {
        "settlement_ratio": float(fit.ratio), "settlement_time": float(fit.T), "settlement_identified": True}},
        "identification": {"payload_kg": float(payload), "rms_mm": 1e3 * float(fit.rms),
                           "s_final_mm": [1e3 * float(v) for v in fit.s_final]}}, sort_keys=False))
    os.replace(tmp, path)                              # a reader sees the whole file or none


def read_parameters(path) -> dict:
    import yaml

    values = yaml.safe_load(Path(path).read_text())["load_compensation"]["ros__parameters"]
    return {k: float(values[k]) for k in NAMES}


def identified(outdir, robot_name: str, plant: str, seed: int) -> tuple[dict, bool]:
    """The settlement identified on (robot, plant, seed) -> (the cases' settlement record, reused):
    the parameter file (identified now, under a file lock, if the output directory has none)."""
    path = parameter_path(outdir, robot_name, plant, seed)
    reused = plant_cache.identified_once(path, lambda p: identify_on_plant(robot_name, plant, seed, p))
    return {"source": "identified", "file": str(path), **read_parameters(path)}, reused


def lc_values(record: dict) -> dict:
    """The load_compensation parameters a case's record sets over the parameter file ({}: shipped)."""
    if record.get("source", "shipped") == "shipped":
        return {}
    return {**{k: float(record[k]) for k in NAMES}, "settlement_identified": True}


def text(record: dict) -> str:
    """One phrase: which settlement model a case ran with."""
    if record.get("source", "shipped") == "shipped":
        return "settlement model of the parameter file"
    return (f"settlement identified on the plant (ratio {record['settlement_ratio']:.3g}, "
            f"T {record['settlement_time']:.3g} s; in the pose estimator)")

"""Which cases the sweep runs, and running them (in up to MAX_JOBS processes).

Each pose of a robot's grid runs each family once; the plant (mismatched seeds, nominal), the
contact force and floor stiffness, the payload fraction and the push direction are assigned round
robin over the poses. With the default four plants (three seeds and nominal), 9 contact variants
and 3 payload fractions, every (plant, variant) pair of a family occurs within 36 poses (4 and 9
are coprime). The program family runs once per plant and controller, from home to one of the
grid's border poses nearest home and back (the plants take turns over those poses).
"""
from __future__ import annotations

import itertools
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import replace

import numpy as np

from cdpr_control.model.robot import load_robot

from cdpr_tools.validate.cases import (CONTACT_FRACTIONS, FAMILIES, FLOOR_STIFFNESS, PAYLOAD_FRACTIONS, PUSH_DIRECTIONS, CaseResult, CaseSpec, run_case)
from cdpr_tools.validate.friction import FAMILIES as FRICTION_FAMILIES
from cdpr_tools.validate.grid import sweep_poses

ROBOTS = ("ipanema3", "ipanema3_mini")
DEFAULT_POSES = 40
DEFAULT_SEEDS = (1, 2, 3)
MAX_JOBS = 2
PROGRAM_CONTROLLERS = ("force_control", "ik_only")
PROGRAM_BORDER_POSES = 4     # the nearest border poses the programs take turns over


def plants(kind: str = "both", seeds=DEFAULT_SEEDS) -> list[tuple[str, int]]:
    """(plant, seed) pairs: the mismatched plant once per seed, the nominal one (seed 0)."""
    if kind not in ("both", "mismatched", "nominal"):
        raise ValueError(f"--plant must be both, mismatched or nominal, got {kind!r}")
    out = [("mismatched", int(s)) for s in seeds] if kind in ("both", "mismatched") else []
    return out + ([("nominal", 0)] if kind in ("both", "nominal") else [])


def plan(robot_name: str, families=FAMILIES, plant_list=None, n_poses: int = DEFAULT_POSES) -> tuple[list, list]:
    """(poses, specs) of one robot: its grid and the cases to run on it."""
    plant_list = plant_list or plants()
    robot = load_robot(robot_name)
    poses = sweep_poses(robot, n_poses)
    contact = list(itertools.product(CONTACT_FRACTIONS, FLOOR_STIFFNESS))
    specs = []
    for p in poses:
        plant, seed = plant_list[p.index % len(plant_list)]
        variants = {"contact": dict(zip(("fraction", "stiffness"), contact[p.index % len(contact)])),
                    "guiding": {"direction": PUSH_DIRECTIONS[p.index % len(PUSH_DIRECTIONS)]},
                    "payload": {"fraction": PAYLOAD_FRACTIONS[p.index % len(PAYLOAD_FRACTIONS)]}}
        for family in families:
            if family in variants:
                specs.append(CaseSpec(family, robot_name, p.index, p.x.tolist(), p.border, plant, seed, variants[family]))
    programs = []
    if "program" in families:
        border = sorted((p for p in poses if p.border), key=lambda p: np.linalg.norm(p.x[:3] - robot.home[:3]))
        targets = [p.x[:3].tolist() for p in border[:PROGRAM_BORDER_POSES]]
        for j, (plant, seed) in enumerate(plant_list if targets else ()):
            for controller in PROGRAM_CONTROLLERS:
                programs.append(CaseSpec("program", robot_name, -1, list(robot.home), True, plant, seed,
                                         {"controller": controller, "poses": [targets[j % len(targets)]]}))
    # the programs among the poses' cases, so that an interrupted sweep has some of every family
    for j, spec in enumerate(programs):
        specs.insert(min(len(specs), (3 * j + 2) * len(families)), spec)
    return poses, specs


def check_jobs(jobs: int) -> None:
    if not 1 <= jobs <= MAX_JOBS:
        raise ValueError(f"--jobs must be 1..{MAX_JOBS} (the machine's cores are shared), got {jobs}")


def run_all(specs, jobs: int = 1, progress=None, log=None) -> list[CaseResult]:
    """Run the cases, in ``jobs`` processes (1: in this one); ``progress(done, total, result)``
    and ``log(results)`` (the case's results) after each."""
    check_jobs(jobs)
    results = []
    if jobs == 1:
        for spec in specs:
            out = _timed(spec)
            results += out
            if log:
                log(out)
            if progress:
                progress(len(results), len(specs), results[-1])
        return results
    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(_timed, spec) for spec in specs]
        for done, future in enumerate(as_completed(futures), 1):
            out = future.result()
            results += out
            if log:
                log(out)
            if progress:
                progress(done, len(specs), results[-1])
    return results


def _timed(spec: CaseSpec) -> list[CaseResult]:
    start, cpu = time.perf_counter(), time.process_time()
    out = run_case(spec)
    for r in out:
        r.wall_s, r.cpu_s = time.perf_counter() - start, time.process_time() - cpu
    return out


def validate(robots, families, plant_list, n_poses: int, jobs: int, outdir, progress=None, command: str = "cdpr validate",
             friction_mode: str = "identified", log=print, settlement_mode: str = "identified"):
    """Plan, run and report the sweep -> (results, the JSON document, figure paths).

    The guiding and payload families run with ``friction_mode``'s friction (:mod:`.friction`): identified, the
    friction of each (robot, plant, seed) among its cases is identified before the cases run
    (:func:`with_identified`; reused from ``outdir`` when there); its time is the meta's
    ``identification_wall_s``, not the cases' ``wall_s``. The payload family likewise runs with ``settlement_mode``'s
    cable settlement (:mod:`.settlement`), identified in the same processes as the friction."""
    import platform

    from cdpr_tools.validate import report

    check_jobs(jobs)
    per_robot = [plan(robot, families, plant_list, n_poses)[1] for robot in robots]
    specs = [spec for group in itertools.zip_longest(*per_robot) for spec in group if spec is not None]
    start = time.perf_counter()
    specs, frictions, settlements = with_identified(specs, friction_mode, settlement_mode, outdir, jobs, log)
    identification_wall = time.perf_counter() - start
    start = time.perf_counter()
    with report.CaseLog(outdir) as case_log:
        results = run_all(specs, jobs, progress, case_log.write)
    meta = {"command": command, "robots": list(robots), "families": list(families),
            "plants": [list(p) for p in plant_list], "poses": n_poses, "jobs": jobs,
            "wall_s": time.perf_counter() - start, "cpu_s": cpu_seconds(results), "host": platform.node(),
            "identification_wall_s": identification_wall,
            "friction": {"mode": friction_mode, "families": list(FRICTION_FAMILIES),
                         "plants": frictions},
            "settlement": {"mode": settlement_mode, "families": ["payload"], "plants": settlements}}
    doc, figures = report.write(results, meta, outdir)
    return results, doc, figures


IDENTIFIED_FAMILIES = {"friction": FRICTION_FAMILIES, "settlement": ("payload",)}


def with_identified(specs, friction_mode: str, settlement_mode: str, outdir, jobs: int = 1,
                    log=print) -> tuple[list, dict, dict]:
    """The specs with what is identified on their plants -> (specs, frictions, settlements), each
    {"<robot> <plant>": record}. ``friction_mode`` identified: the cases of FRICTION_FAMILIES get the
    pulley friction identified on their (robot, plant, seed) (:attr:`CaseSpec.friction`,
    :mod:`.friction`); ``settlement_mode`` identified: the payload cases the cable settlement
    (:attr:`CaseSpec.settlement`, :mod:`.settlement`, about 10 s CPU each); shipped: the robot's and
    parameter file's. Each is identified once, all of them together in ``jobs`` processes (they are
    independent runs), or reused from ``outdir``."""
    from cdpr_tools.validate import friction, settlement

    modes = {"friction": (friction_mode, friction), "settlement": (settlement_mode, settlement)}
    for kind, (mode, module) in modes.items():
        if mode not in module.MODES:
            raise ValueError(f"--{kind} must be one of {', '.join(module.MODES)}, got {mode!r}")
    tasks = [(kind, key) for kind, (mode, _) in modes.items() if mode == "identified"
             for key in sorted({(s.robot, s.plant, s.seed) for s in specs if s.family in IDENTIFIED_FAMILIES[kind]})]
    if jobs == 1 or len(tasks) < 2:
        records = [_identified(outdir, kind, *key) for kind, key in tasks]
    else:
        with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            records = list(pool.map(_identified, [outdir] * len(tasks), *zip(*((kind, *key) for kind, key in tasks))))
    by_kind = {"friction": {}, "settlement": {}}
    for (kind, key), (record, reused) in zip(tasks, records):
        by_kind[kind][key] = record
        log(f"[validate] {_plant_name(*key)}: {kind} {'reused from' if reused else 'identified into'} "
            f"{record['file']}; {_identified_text(kind, record)}")
    specs = [replace(s, **{kind: by_kind[kind][(s.robot, s.plant, s.seed)] for kind in by_kind
                           if s.family in IDENTIFIED_FAMILIES[kind] and (s.robot, s.plant, s.seed) in by_kind[kind]})
             for s in specs]
    return specs, *({_plant_name(*key): record for key, record in by_kind[kind].items()} for kind in by_kind)


def _identified(outdir, kind: str, robot: str, plant: str, seed: int) -> tuple[dict, bool]:
    """(record, reused) of ``kind`` (friction or settlement) on (robot, plant, seed): one process's task."""
    from cdpr_tools.validate import friction, settlement

    return {"friction": friction, "settlement": settlement}[kind].identified(outdir, robot, plant, seed)


def _identified_text(kind: str, record: dict) -> str:
    if kind == "friction":
        d = record["deviation_percent"]
        return f"mu / sigma / F_pv up to {d['mu']:.3g} / {d['sigma']:.3g} / {d['F_pv']:.3g} % from the robot file's"
    return f"ratio {record['settlement_ratio']:.3g}, T {record['settlement_time']:.3g} s"


def _plant_name(robot: str, plant: str, seed: int) -> str:
    return f"{robot} {plant}" + (f" seed {seed}" if plant != "nominal" else "")


def cpu_seconds(results) -> float:
    """CPU time [s] of the cases (a payload case's two results share one)."""
    seen = {}
    for r in results:
        seen[(r.spec.family, r.spec.robot, r.spec.pose_index, r.spec.plant, r.spec.seed,
              r.spec.variant.get("fraction"), r.spec.variant.get("stiffness"))
             if r.spec.family == "payload" else id(r)] = r.cpu_s
    return float(sum(seen.values()))

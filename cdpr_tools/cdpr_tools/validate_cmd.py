"""``cdpr validate``: the validation sweep of issue 25 (contact, hand guiding, payloads, a program)
over each shipped robot's wrench-feasible workspace, both plants, in process (docs/validation.md).

Exit status 1 when any case is out of its band (or diverged, was refused or could not run), 0 when
every case is within; a one-line summary per family on stdout, JSON, one line per case and two
figures per family (the map of the poses, the distribution of its main criteria) in the output
directory. ``--figures SWEEP`` renders those figures from an earlier sweep's output directory.
"""
from __future__ import annotations

import math
import sys

from cdpr_tools.validate.cases import FAMILIES
from cdpr_tools.validate.friction import MODES as FRICTION_MODES
from cdpr_tools.validate.settlement import MODES as SETTLEMENT_MODES
from cdpr_tools.validate.sweep import DEFAULT_POSES, DEFAULT_SEEDS, MAX_JOBS, ROBOTS

DEFAULT_OUT = "out/validation"


def add_parser(sub) -> None:
    p = sub.add_parser("validate", help="run the validation sweep (contact, guiding, payload, program) over the workspace",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default=",".join(ROBOTS), help=f"robots, comma separated (default {','.join(ROBOTS)})")
    p.add_argument("--family", default=",".join(FAMILIES), help=f"case families, comma separated (default {','.join(FAMILIES)})")
    p.add_argument("--plant", default="both", help="both (default), mismatched or nominal")
    p.add_argument("--seeds", default=",".join(map(str, DEFAULT_SEEDS)),
                   help="seeds of the mismatched plant, comma separated (default 1,2,3)")
    p.add_argument("--poses", type=int, default=DEFAULT_POSES,
                   help=f"poses per robot (default {DEFAULT_POSES}; fewer: the first N of the grid, a third or more near the border)")
    p.add_argument("--jobs", type=int, default=1, help=f"processes, 1..{MAX_JOBS} (default 1)")
    p.add_argument("--friction", default="identified", choices=FRICTION_MODES,
                   help="the guiding and payload cases' pulley friction: identified on each plant first, as a user runs the robot, "
                   "the parameter files cached in OUTPUT/friction/ (default), or shipped (the robot file's)")
    p.add_argument("--settlement", default="identified", choices=SETTLEMENT_MODES,
                   help="the payload cases' cable settlement: identified on each plant first, as a user runs the "
                   "robot (`cdpr identify settlement`, cached in OUTPUT/settlement/; it then goes to the pose "
                   "estimator and, under force control, out of the command: docs/validation.md, \"Payload after "
                   "session 15\"; the default) or shipped (the parameter file's model, never in the pose estimator)")
    p.add_argument("-o", "--output", default=DEFAULT_OUT, help=f"directory for JSON, text and PNG (default {DEFAULT_OUT})")
    p.add_argument("--from-cases", metavar="FILE",
                   help="report the cases.jsonl of an earlier (or interrupted) run instead of running")
    p.add_argument("--figures", metavar="SWEEP",
                   help="render the figures of an earlier sweep (its output directory, or its cases.jsonl) into "
                   "-o instead of running: per family the pass/fail map of the poses and the distribution of its "
                   "main criteria (e.g. --figures out/validation -o docs/figures)")
    p.set_defaults(run=run)


def _names(text: str, known, what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise ValueError(f"--{what}: unknown {', '.join(unknown) or '(none given)'}; choose from {', '.join(known)}")
    return names


def _seeds(text: str) -> list[int]:
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"--seeds: integers separated by commas, got {text!r}") from None
    if not seeds or min(seeds) < 1:
        raise ValueError(f"--seeds: at least one seed, each >= 1, got {text!r}")
    return seeds


def run(args) -> int:
    from cdpr_tools.progress import Progress
    from cdpr_tools.validate.sweep import plants, validate

    if args.figures:
        return _figures(args)
    if args.from_cases:
        return _report_cases(args)
    robots = _names(args.robot, ROBOTS, "robot")
    families = _names(args.family, FAMILIES, "family")
    plant_list = plants(args.plant, _seeds(args.seeds))
    if args.poses < 3:
        raise ValueError(f"--poses must be >= 3, got {args.poses}")
    print(f"[validate] {', '.join(robots)}; {', '.join(families)}; {args.poses} poses per robot; plants "
          f"{', '.join(p if p == 'nominal' else f'{p} seed {s}' for p, s in plant_list)}; {args.jobs} job(s); "
          f"guiding and payload with {args.friction} friction; payload with {args.settlement} settlement", flush=True)
    progress = Progress("validate")
    command = "cdpr " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["validate"] else "cdpr validate"
    try:
        results, doc, figures = validate(robots, families, plant_list, args.poses, args.jobs, args.output,
                                         lambda done, total, r: progress.update(done / total, f"{r.spec.family} {r.status}"),
                                         command, args.friction, lambda line: print(line, flush=True),
                                         args.settlement)
    finally:
        progress.done()
    return _summarise(results, doc, figures, args.output)


def _summarise(results, doc, figures, outdir) -> int:
    from cdpr_tools.validate import report

    for family, s in doc["summary"].items():
        print(report.summary_line(family, s))
    cpu = doc["meta"]["cpu_s"]
    cpu = f"{cpu:.0f} s CPU" if math.isfinite(cpu) else "CPU time not recorded"
    meta = doc["meta"]
    ident = meta.get("identification_wall_s")
    ident = (f" after {ident:.0f} s identifying the plants ({(ident + meta['wall_s']) / 60.0:.1f} min in all)"
             if ident is not None else "")
    print(f"[validate] {len(results)} cases in {meta['wall_s']:.0f} s wall, {cpu}{ident}; "
          f"{outdir}/validation.json, "
          "validation.txt, " + ", ".join(f.name for f in figures))
    # a refused case is not applicable (its reason is in the report), not out of the bands
    return 0 if all(r.passed or not report.applicable(r) for r in results) else 1


def _report_cases(args) -> int:
    """The report of the cases recorded in a cases.jsonl; its wall time is the sum of the cases'."""
    from pathlib import Path

    from cdpr_tools.validate import report
    from cdpr_tools.validate.friction import FAMILIES as FRICTION_FAMILIES
    from cdpr_tools.validate.sweep import cpu_seconds

    path = Path(args.from_cases)
    if not path.is_file():
        raise ValueError(f"--from-cases: no file {path}")
    results = report.read_cases(path)
    if not results:
        raise ValueError(f"--from-cases: {path} holds no case")
    frictions = {f"{r.spec.robot} {report.plant_name(r)}": r.spec.friction for r in results
                 if r.spec.family in FRICTION_FAMILIES}
    meta = {"command": f"cdpr validate --from-cases {path}", "from_cases": str(path),
            "wall_s": sum(r.wall_s for r in results), "cpu_s": cpu_seconds(results),
            "friction": {"families": list(FRICTION_FAMILIES), "plants": frictions}}
    doc, figures = report.write(results, meta, args.output)
    return _summarise(results, doc, figures, args.output)


def _figures(args) -> int:
    """The figures of an earlier sweep (:func:`cdpr_tools.validate.figures.from_sweep`)."""
    from cdpr_tools.validate.figures import from_sweep

    paths = from_sweep(args.figures, args.output)
    print(f"[validate] {len(paths)} figures in {args.output}: " + ", ".join(p.name for p in paths))
    return 0

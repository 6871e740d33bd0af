"""Hand guiding on the IPAnema 3's mismatched plants with the shipped and with the identified friction.

For each mismatched plant seed the friction run is recorded on that plant
(`cdpr_tools.identify.experiments.record_friction_run(..., plant_seed=N)`) and fitted as
`cdpr identify friction --robot ipanema3 -o` does; the sweep's guiding cases
(`cdpr_tools.validate.cases.guiding_case`, the grid and plant assignment of `cdpr validate`) then run
with the friction compensation given either the robot file's pulley friction ("shipped") or the
seed's identified parameter file ("identified"). Prints one JSON line per case and a summary;
docs/validation.md ("Friction identification after session 10") quotes it.

    python scripts/guiding_identified_friction.py --friction-dir out/friction [--poses 40] [--only 1,5] \
        [--which shipped,identified]

Parameter files already in --friction-dir (friction_seed<N>.yaml) are used as they are.
"""
from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

ROBOT = "ipanema3"


def identified_file(directory: Path, seed: int) -> Path:
    """The friction_compensation parameter file identified on plant seed ``seed`` (made if missing)."""
    from cdpr_control.kernels.jit import njit
    from cdpr_control.model.robot import load_robot
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify import experiments, friction

    path = directory / f"friction_seed{seed}.yaml"
    if not path.exists():
        robot = load_robot(ROBOT)
        bag = experiments.record_friction_run(directory / f"friction_run_seed{seed}", robot, seed=seed, plant_seed=seed)
        _, fits = friction.identify(BagReader(bag), robot, jit=njit, progress=print)
        friction.write_parameter_file(fits, path)
    return path


def main() -> int:
    import cdpr_sim.hand_guiding as hand_guiding
    from cdpr_control.control.params import shipped_configuration
    from cdpr_tools.validate import cases
    from cdpr_tools.validate.sweep import plan, plants

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--friction-dir", required=True, type=Path)
    p.add_argument("--poses", type=int, default=40, help="grid poses (the sweep's first N)")
    p.add_argument("--only", help="pose indices, comma separated (default: every mismatched one)")
    p.add_argument("--which", default="shipped,identified")
    args = p.parse_args()
    args.friction_dir.mkdir(parents=True, exist_ok=True)
    only = None if not args.only else {int(i) for i in args.only.split(",")}
    _, specs = plan(ROBOT, ("guiding",), plants(), args.poses)          # the sweep's plant per pose
    specs = [s for s in specs if s.plant == "mismatched" and (only is None or s.pose_index in only)]
    original, loop = hand_guiding.guiding_run, shipped_configuration(ROBOT).loop
    results = {}
    for which in args.which.split(","):
        for spec in specs:
            params = None
            if which == "identified":
                values = yaml.safe_load(identified_file(args.friction_dir, spec.seed).read_text())
                values = values["friction_compensation"]["ros__parameters"]
                params = replace(loop, friction=replace(loop.friction, **{k: np.array(v) for k, v in values.items()}))
            # the case runs the library's runner; only its loop's friction compensation differs
            hand_guiding.guiding_run = (original if params is None else
                                        lambda *a, _p=params, **k: original(*a, **{**k, "loop_params": _p}))
            try:
                r = cases.guiding_case(spec)
            finally:
                hand_guiding.guiding_run = original
            results[which, spec.pose_index] = r
            m = {k: (round(v, 3) if np.isfinite(v) else None) for k, v in r.metrics.items()}
            print(json.dumps({"which": which, "pose": spec.pose_index, "x": [round(v, 3) for v in spec.x],
                              "border": spec.border, "seed": spec.seed, "status": r.status, "metrics": m,
                              "note": r.note}), flush=True)
    for which in args.which.split(","):
        rs = [r for (w, _), r in results.items() if w == which]
        e = [r.metrics["eigenfrequency_error_percent"] for r in rs]
        measured = [v for v in e if np.isfinite(v)]
        worst = max(measured, key=abs) if measured else float("nan")
        out_of_band = sum(not r.checks.get("eigenfrequency_error_percent", False) for r in rs)
        print(f"{which}: {sum(r.passed for r in rs)}/{len(rs)} passed; eigenfrequency error measured in "
              f"{len(measured)}, out of band {out_of_band}, worst {worst:+.2f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

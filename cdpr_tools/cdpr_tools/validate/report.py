"""The sweep's results: JSON, one line per case (text), one summary line per family, the pass
rates per robot and plant, and two figures per family (:mod:`.figures`)."""
from __future__ import annotations

import json
import re
from dataclasses import asdict
from pathlib import Path

import numpy as np

from cdpr_tools.validate.cases import CaseResult
from cdpr_tools.validate.criteria import band_for
from cdpr_tools.validate.friction import FAMILIES as FRICTION_FAMILIES

SAG_RESIDUAL = "sag_residual_beyond_accuracy_mm"     # a payload case whose sag was below the resolution

# the metric a family's summary line and figure show
HEADLINE = {"contact": "overshoot_percent", "guiding": "rest_wrench_percent",
            "payload": "estimate_error_percent", "program": "position_error_max_mm"}


def where(r: CaseResult) -> str:
    """The case's robot, pose, plant and variant, in one phrase."""
    s = r.spec
    if s.pose_index < 0:                        # a program: its border targets
        pose = "program to " + ", ".join("[" + ", ".join(f"{v:.3f}" for v in x[:3]) + "]" for x in s.variant["poses"])
    else:
        pose = f"#{s.pose_index} [{', '.join(f'{v:.3f}' for v in s.x[:3])}]"
    if s.pose_index >= 0 and s.x[5]:
        pose += f" c {np.rad2deg(s.x[5]):+.0f} deg"
    plant = "nominal" if s.plant == "nominal" else f"mismatched seed {s.seed}"
    variant = ", ".join(f"{k} {_short(v)}" for k, v in s.variant.items() if k != "poses")
    if s.family in FRICTION_FAMILIES:           # which friction the compensation had (validate.friction)
        variant += f", friction {s.friction.get('source', 'shipped')}"
    return f"{s.robot} {pose}{' (border)' if s.border and s.pose_index >= 0 else ''}, {plant}, {variant}"


def _short(v) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, (tuple, list)):
        return "(" + " ".join(f"{a:g}" for a in v) + ")"
    return str(v)


def badness(metric: str, value: float, plant: str) -> float:
    """How far a measured value is on the bad side of its band (larger is worse; an infinite
    value, such as a force that never settled, is worst). NaN (not measured) has no badness: the
    callers leave it out."""
    band = band_for(metric, plant)
    if band is None:
        return value
    if band.lo is not None and band.hi is not None:
        return abs(value - 0.5 * (band.lo + band.hi))
    return value if band.lo is None else -value


def _measured(value) -> bool:
    """A metric value that was measured: a number, infinite included (NaN or None: not measured)."""
    return value is not None and not np.isnan(float(value))


def applicable(r: CaseResult) -> bool:
    """A case the configuration applies to: every case but a refused one (a controller the shipped
    configuration refuses at the pose, a payload below the pose's capacity ...: "not applicable",
    with its reason, reported apart from the failures)."""
    return r.status != "refused"


def refusal_reason(r: CaseResult) -> str:
    """The reason of a refused case without its figures: its note up to the first figure, colon or
    parenthesis ("dynamic capacity", "IK-only control does not hold this pose's cables tensed
    before any payload")."""
    return re.split(r"[:;(]|\d", r.note, maxsplit=1)[0].strip() or "refused"


def family_summary(results: list[CaseResult], family: str) -> dict:
    """Counts by status, the pass rate over all cases and over the applicable ones (refused cases
    are "not applicable", counted with their reasons), the cases whose sag was below the
    resolution, and per metric: mean over the finite values, and for a metric with a band its worst
    value and where, for one without its range."""
    rs = [r for r in results if r.spec.family == family]
    counts = {s: sum(r.status == s for r in rs) for s in ("passed", "failed", "diverged", "held", "refused", "error")}
    n_applicable = sum(applicable(r) for r in rs)
    reasons: dict[str, int] = {}
    for r in rs:
        if not applicable(r):
            reasons[refusal_reason(r)] = reasons.get(refusal_reason(r), 0) + 1
    out = {"cases": len(rs), **counts, "pass_rate": counts["passed"] / len(rs) if rs else float("nan"),
           "applicable": n_applicable, "not_applicable": len(rs) - n_applicable,
           "pass_rate_applicable": counts["passed"] / n_applicable if n_applicable else float("nan"),
           "not_applicable_reasons": reasons,
           "sag_below_resolution": sum(1 for r in rs if SAG_RESIDUAL in r.metrics), "metrics": {}}
    names = sorted({m for r in rs for m in r.metrics})
    for name in names:
        have = [r for r in rs if name in r.metrics]
        measured = [r for r in have if _measured(r.metrics[name])]
        values = np.array([r.metrics[name] for r in measured], dtype=float)
        finite = values[np.isfinite(values)]
        m = {"mean": float(finite.mean()) if len(finite) else None,
             "out_of_band": sum(1 for r in have if not r.checks.get(name, True)),
             "not_measured": len(have) - len(measured)}
        judged = [r for r in measured if band_for(name, r.spec.plant, r.spec.variant.get("controller"))]
        if any(band_for(name, r.spec.plant, r.spec.variant.get("controller")) for r in have):
            if judged:
                worst = max(judged, key=lambda r: badness(name, float(r.metrics[name]), r.spec.plant))
                m.update(worst=float(worst.metrics[name]), where=where(worst))
        elif len(finite):
            m.update(min=float(finite.min()), max=float(finite.max()))
        out["metrics"][name] = m
    return out


def summary_line(family: str, s: dict) -> str:
    """One line: pass rate, the headline metric's mean and worst case with where, failures per metric."""
    if s.get("applicable") is None:                      # a summary written before the applicable counts
        line = f"{family}: {s['passed']}/{s['cases']} passed ({100.0 * s['pass_rate']:.0f} %)"
    else:
        rate = f"{100.0 * s['pass_rate_applicable']:.0f} %" if s["applicable"] else "none applicable"
        line = (f"{family}: {s['passed']}/{s['applicable']} applicable passed ({rate}; "
                f"{s['passed']}/{s['cases']} of all)")
    extra = [f"{s[k]} {k}" for k in ("diverged", "held", "error") if s[k]]
    if extra:
        line += " [" + ", ".join(extra) + "]"
    if s["refused"]:
        reasons = s.get("not_applicable_reasons") or {"refused": s["refused"]}
        line += f"; not applicable {s['refused']} (" + ", ".join(f"{n}: {k}" for k, n in reasons.items()) + ")"
    if s.get("sag_below_resolution"):
        residual = s["metrics"].get(SAG_RESIDUAL, {})
        line += f"; sag below resolution {s['sag_below_resolution']}"
        if residual.get("worst") is not None:
            line += f" (residual beyond the static accuracy worst {residual['worst']:.3g} mm at {residual['where']})"
    m = s["metrics"].get(HEADLINE[family])
    if m and "worst" in m:
        mean = f"mean {m['mean']:.3g}, " if m["mean"] is not None else ""
        line += f"; {HEADLINE[family]} {mean}worst {m['worst']:.3g} at {m['where']}"
    elif m and "max" in m:
        line += f"; {HEADLINE[family]} mean {m['mean']:.3g}, {m['min']:.3g} .. {m['max']:.3g}"
    if m and m["not_measured"]:
        line += f"; {HEADLINE[family]} not measured in {m['not_measured']} case{'s' if m['not_measured'] > 1 else ''}"
    fails = [f"{name} {m['out_of_band']}" for name, m in s["metrics"].items() if m["out_of_band"] and name != "diverged"]
    if fails:
        line += "; out of band: " + ", ".join(fails)
    return line


def case_line(r: CaseResult) -> str:
    """One line: family, status (a refused case: "n/a", its note "not applicable: <reason>"), where,
    the metrics ("(out)" where out of band, "(not judged)" where reported only) and the note."""
    if not applicable(r):
        return f"{r.spec.family:8s} {'n/a':8s} {where(r)}: not applicable: {r.note}"
    metrics = ", ".join(f"{k} {f'{v:.4g}' if _measured(v) else 'not measured'}"
                        f"{'' if r.checks.get(k, True) else ' (out)'}" for k, v in r.metrics.items())
    return f"{r.spec.family:8s} {r.status:8s} {where(r)}: {metrics}{' - ' + r.note if r.note else ''}"


def case_dict(r: CaseResult) -> dict:
    return {**asdict(r.spec), "status": r.status, "applicable": applicable(r), "note": r.note, "wall_s": r.wall_s,
            "cpu_s": r.cpu_s, "metrics": r.metrics, "checks": r.checks}


class CaseLog:
    """cases.jsonl in the output directory: one JSON line per case as it ends, so that an
    interrupted sweep keeps what it measured (``cdpr validate --from-cases`` reports it)."""

    def __init__(self, outdir):
        self.path = Path(outdir) / "cases.jsonl"

    def __enter__(self):
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.file = self.path.open("w")
        return self

    def write(self, results) -> None:
        for r in results:
            self.file.write(dumps(case_dict(r)) + "\n")
        self.file.flush()

    def __exit__(self, *exc):
        self.file.close()


def read_cases(path) -> list[CaseResult]:
    """The cases of a cases.jsonl (lines cut off by an interrupted run are skipped)."""
    from cdpr_tools.validate.cases import CaseSpec

    results = []
    for line in Path(path).read_text().splitlines():
        try:
            d = json.loads(line)
        except json.JSONDecodeError:
            continue
        # (a case recorded before the sweep recorded its friction ran with the robot file's: the default)
        spec = CaseSpec(**{k: d[k] for k in CaseSpec.__dataclass_fields__ if k in d})
        metrics = {k: float("nan") if v is None else float(v) for k, v in d["metrics"].items()}
        results.append(CaseResult(spec, metrics, d["checks"], d["status"], d["note"], d["wall_s"],
                                  d.get("cpu_s", float("nan"))))
    return results


def to_json(results: list[CaseResult], meta: dict) -> dict:
    families = sorted({r.spec.family for r in results}, key=list(HEADLINE).index)
    return {"meta": meta,
            "summary": {f: family_summary(results, f) for f in families},
            "per_robot_plant": {f"{robot} {plant}": {f: _rate([r for r in results if r.spec.family == f
                                                              and r.spec.robot == robot and plant_name(r) == plant])
                                                      for f in families}
                                for robot in sorted({r.spec.robot for r in results})
                                for plant in sorted({plant_name(r) for r in results})},
            "cases": [case_dict(r) for r in results]}


def plant_name(r: CaseResult) -> str:
    return "nominal" if r.spec.plant == "nominal" else f"mismatched seed {r.spec.seed}"


def _rate(rs) -> str:
    """passed/applicable, and the not applicable (refused) cases where there are any: "9/12 (8 n/a)"."""
    if not rs:
        return "-"
    n_a = sum(not applicable(r) for r in rs)
    return f"{sum(r.passed for r in rs)}/{len(rs) - n_a}" + (f" ({n_a} n/a)" if n_a else "")


def write(results: list[CaseResult], meta: dict, outdir) -> tuple[dict, list[Path]]:
    """validation.json, validation.txt (one line per case) and per family its map and distribution
    figures (:func:`cdpr_tools.validate.figures.render`) in outdir."""
    from cdpr_tools.validate.figures import render

    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    doc = to_json(results, meta)
    (outdir / "validation.json").write_text(dumps(doc, indent=1))
    (outdir / "validation.txt").write_text("\n".join(case_line(r) for r in results) + "\n")
    figures = render(results, outdir)
    return doc, figures


def dumps(doc, **kwargs) -> str:
    """JSON text of ``doc`` without NaN or Infinity (JSON has neither): NaN (not measured) as null,
    an infinite value (a force that never settled) as the string "inf" or "-inf"."""
    return json.dumps(_finite(doc), allow_nan=False, default=_json_default, **kwargs)


def _finite(v):
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite(x) for x in v]
    if isinstance(v, np.ndarray):
        return _finite(v.tolist())
    if isinstance(v, (float, np.floating)):
        if np.isnan(v):
            return None
        return float(v) if np.isfinite(v) else ("inf" if v > 0 else "-inf")
    return v


def _json_default(v):
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)

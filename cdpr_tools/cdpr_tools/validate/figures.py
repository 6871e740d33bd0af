"""The sweep's figures (``cdpr validate``, and ``cdpr validate --figures DIR`` from an earlier sweep's
output directory): per case family

* ``validation_<family>.png``, the map: every robot's poses over its workspace seen from above (x-y)
  and from the side (x-z), coloured passed / failed / not applicable (a pose with several cases:
  failed when any applicable one failed), border poses (within 10 % of the hull's border,
  :mod:`.grid`) drawn as diamonds, the program family's border targets joined to home, and the
  worst case of the family's main criterion annotated with its value, pose and plant;
* ``validation_<family>_distribution.png``: the distribution of the family's main criteria
  (:data:`CRITERIA`) per robot and plant, one point per case, the band of
  :mod:`.criteria` shaded, the mean per plant marked, the worst case and where written under the
  panel's title.

Everything is drawn from the cases (``cases.jsonl``), none from one pose; each figure's title
names the robots and the plants its cases ran on.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cdpr_tools.validate.cases import CaseResult
from cdpr_tools.validate.criteria import band_for
from cdpr_tools.validate.report import HEADLINE, badness, read_cases

# the main criteria of a family: the first one is the map's annotated worst case
CRITERIA = {"contact": ("overshoot_percent",),
            "guiding": ("rest_wrench_percent", "eigenfrequency_error_percent"),
            "payload": ("estimate_error_percent", "sag_cut_percent"),
            "program": ("force_below_f_min_N", "position_error_max_mm")}
LABELS = {"overshoot_percent": "contact force overshoot [%]",
          "rest_wrench_percent": "user wrench at rest [% of w_max]",
          "eigenfrequency_error_percent": "eigenfrequency error to (5.12) [%]",
          "estimate_error_percent": "estimate error from 1 s after the step [%]",
          "sag_cut_percent": "sag cut [%]",
          "force_below_f_min_N": "lowest cable force below f_min [N]",
          "position_error_max_mm": "largest position error [mm]"}
UNITS = {"percent": "%", "mm": "mm", "N": "N", "s": "s", "kg": "kg", "Hz": "Hz"}
OUTCOMES = {"passed": "tab:green", "failed": "tab:red", "n/a": "0.6"}
SCREEN_DPI = 100                     # figures of at most 1200 x 900 px at this resolution


def label(metric: str) -> str:
    """The metric's axis label with its unit (the unit is the last word of its name)."""
    if metric in LABELS:
        return LABELS[metric]
    name, _, unit = metric.rpartition("_")
    return f"{name.replace('_', ' ')} [{UNITS.get(unit, unit)}]" if unit in UNITS else f"{metric} [-]"


def outcome(r: CaseResult) -> str:
    """passed, failed (failed, diverged, held, error) or n/a (refused: not applicable)."""
    if r.status == "refused":
        return "n/a"
    return "passed" if r.passed else "failed"


def plant_label(r: CaseResult) -> str:
    return "nominal" if r.spec.plant == "nominal" else f"seed {r.spec.seed}"


def plants_text(rs) -> str:
    """The plants of some cases, for a title: "mismatched seeds 1, 2, 3 and nominal"."""
    seeds = sorted({r.spec.seed for r in rs if r.spec.plant != "nominal"})
    parts = [f"mismatched seed{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))}"] if seeds else []
    if any(r.spec.plant == "nominal" for r in rs):
        parts.append("nominal")
    return " and ".join(parts) + (" plant" if len(parts) == 1 and not seeds else " plants")


def position(r: CaseResult) -> np.ndarray:
    """Where the case ran: its pose, or the program's (first) border target."""
    return np.asarray(r.spec.variant["poses"][0] if r.spec.pose_index < 0 else r.spec.x[:3], dtype=float)


def worst_case(rs, metric: str) -> CaseResult | None:
    """The case whose measured value of ``metric`` lies farthest on the bad side of its band (an
    infinite value worst; the summary's worst case, :func:`.report.badness`); None when no case has
    a judged, measured value."""
    judged = [r for r in rs if metric in r.metrics and not np.isnan(float(r.metrics[metric]))
              and band_for(metric, r.spec.plant, r.spec.variant.get("controller")) is not None]
    if not judged:
        return None
    return max(judged, key=lambda r: badness(metric, float(r.metrics[metric]), r.spec.plant))


def where_short(r: CaseResult) -> str:
    """Pose (or program target), border, plant and the variant's controller, short."""
    p = ", ".join(f"{v:.2f}" for v in position(r))
    pose = f"program to [{p}]" if r.spec.pose_index < 0 else f"#{r.spec.pose_index} [{p}]"
    border = " border" if r.spec.border and r.spec.pose_index >= 0 else ""
    extra = ", ".join(f"{k} {v:g}" for k, v in r.spec.variant.items() if isinstance(v, float))
    controller = r.spec.variant.get("controller")
    return ", ".join(s for s in (f"{pose}{border}", "nominal" if r.spec.plant == "nominal"
                                 else f"mismatched seed {r.spec.seed}", controller, extra) if s)


def _value_text(metric: str, value: float) -> str:
    unit = label(metric).rsplit("[", 1)[-1].rstrip("]")
    return f"{value:.3g} {unit}" if np.isfinite(value) else "never settled"


def map_figure(results: list[CaseResult], family: str, path: Path) -> Path:
    """Per robot (a column), its poses seen from above (x-y) and from the side (x-z)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from cdpr_control.model.robot import load_robot

    rs_family = [r for r in results if r.spec.family == family]
    robots = sorted({r.spec.robot for r in rs_family})
    fig, axes = plt.subplots(2, len(robots), figsize=(5.8 * len(robots), 8.4), squeeze=False)
    metric = CRITERIA.get(family, (None,))[0]
    for col, name in enumerate(robots):
        rs = [r for r in rs_family if r.spec.robot == name]
        robot = load_robot(name)
        by_pose: dict = {}
        for r in rs:
            by_pose.setdefault(tuple(np.round(position(r), 4)), []).append(r)
        counts = {k: sum(outcome(r) == k for r in rs) for k in OUTCOMES}
        worst = worst_case(rs, metric) if metric else None
        for row, (j, axis) in enumerate(((1, "y"), (2, "z"))):
            ax = axes[row, col]
            if family == "program":
                for key in by_pose:
                    ax.plot([robot.home[0], key[0]], [robot.home[j], key[j]], color="0.75", lw=0.8, zorder=1)
            for key, group in by_pose.items():
                outcomes = {outcome(r) for r in group}
                o = "failed" if "failed" in outcomes else "passed" if "passed" in outcomes else "n/a"
                border = any(r.spec.border for r in group)
                ax.scatter(key[0], key[j], c=OUTCOMES[o], marker="D" if border else "o", s=34 if border else 28,
                           edgecolors="k" if border else "none", linewidths=0.6, zorder=3)
            ax.scatter(robot.home[0], robot.home[j], marker="+", c="k", s=60, zorder=4)
            if worst is not None:                      # ringed; its value and where in the title
                p = position(worst)
                ax.scatter(p[0], p[j], s=220, facecolors="none", edgecolors="k", linewidths=1.4, zorder=5)
                ax.annotate("worst", (p[0], p[j]), xytext=(8, 8), textcoords="offset points", fontsize=8, zorder=5)
            a = robot.a
            pad = 0.03 * float(np.ptp(a[:, [0, j]], axis=0).max())
            ax.set(xlim=(a[:, 0].min() - pad, a[:, 0].max() + pad), ylim=(a[:, j].min() - pad, a[:, j].max() + pad),
                   xlabel="x [m]", ylabel=f"{axis} [m]")
            ax.grid(alpha=0.3)
            view = "from above (x-y)" if axis == "y" else "from the side (x-z)"
            title = f"{name}, {view}; cases passed {counts['passed']}, failed {counts['failed']}, n/a {counts['n/a']}"
            if worst is not None:
                value = float(worst.metrics[metric])
                held = band_for(metric, worst.spec.plant, worst.spec.variant.get("controller")).holds(value)
                title += (f"\nworst {metric} {_value_text(metric, value)} ({'in' if held else 'out of'} band): "
                          f"{where_short(worst)}")
            ax.set_title(title, fontsize=7)
    handles = [Line2D([], [], ls="", marker="o", color=c, label=f"{k}") for k, c in OUTCOMES.items()]
    handles += [Line2D([], [], ls="", marker="D", mfc="w", mec="k", label="border pose (within 10 %)"),
                Line2D([], [], ls="", marker="+", color="k", label="home")]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8)
    fig.suptitle(f"cdpr validate, {family}: the cases over the workspace\n{plants_text(rs_family)} (round robin "
                 "over the poses); a pose with several cases: failed if any failed", fontsize=9)
    fig.tight_layout(rect=(0, 0.04, 1, 0.95))
    fig.savefig(path, dpi=SCREEN_DPI)
    plt.close(fig)
    return path


def distribution_figure(results: list[CaseResult], family: str, path: Path) -> Path:
    """Per criterion (a row) and robot (a column): every case's value by plant, the band shaded,
    the mean per plant as a bar, the worst case and where under the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    rs_family = [r for r in results if r.spec.family == family]
    robots = sorted({r.spec.robot for r in rs_family})
    metrics = [m for m in CRITERIA.get(family, ()) if any(m in r.metrics for r in rs_family)]
    fig, axes = plt.subplots(max(len(metrics), 1), len(robots), figsize=(5.8 * len(robots), 4.0 * max(len(metrics), 1) + 0.6),
                             squeeze=False)
    for row, metric in enumerate(metrics):
        for col, name in enumerate(robots):
            ax = axes[row, col]
            rs = [r for r in rs_family if r.spec.robot == name and metric in r.metrics and outcome(r) != "n/a"]
            plants = sorted({plant_label(r) for r in rs}, key=lambda p: (p == "nominal", p))
            _strip(ax, rs, metric, plants)
            worst = worst_case(rs, metric)
            measured = [float(r.metrics[metric]) for r in rs if not np.isnan(float(r.metrics[metric]))]
            finite = [v for v in measured if np.isfinite(v)]
            text = f"{name}: {len(rs)} cases, {plants_text(rs) if rs else 'none'}"
            if finite:
                text += f"\nmean {np.mean(finite):.3g}"
            if worst is not None:
                text += f", worst {_value_text(metric, float(worst.metrics[metric]))}"
            if len(measured) < len(rs):
                text += f"; not measured in {len(rs) - len(measured)}"
            if worst is not None:
                text += f"\nworst at {where_short(worst)}"
            ax.set_title(text, fontsize=7)
            ax.set(ylabel=label(metric), xlabel="plant (mismatched: its seed)")
    handles = [Line2D([], [], ls="", marker="o", color=c, label=k) for k, c in
               (("in band", "tab:green"), ("out of band", "tab:red"), ("not judged", "0.5"))]
    handles += [Line2D([], [], ls="", marker="D", mfc="w", mec="k", label="border pose"),
                Line2D([], [], color="k", lw=2, label="mean per plant"),
                Line2D([], [], color="tab:green", alpha=0.25, lw=8, label="band")]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8)
    fig.suptitle(f"cdpr validate, {family}: the main criteria per case; {plants_text(rs_family)}", fontsize=9)
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    fig.savefig(path, dpi=SCREEN_DPI)
    plt.close(fig)
    return path


def _strip(ax, rs, metric: str, plants: list[str]) -> None:
    """One column of points per plant (spread sideways), the band of each plant shaded; infinite
    values as triangles at the top of the axis."""
    values = np.array([float(r.metrics[metric]) for r in rs], dtype=float)
    finite = values[np.isfinite(values)]
    bands = {}                 # a plant's band: that of its judged cases (a reference controller's are not)
    for r in rs:
        band = band_for(metric, r.spec.plant, r.spec.variant.get("controller"))
        if band is not None:
            bands.setdefault(plant_label(r), band)
    limits = [v for b in bands.values() if b is not None for v in (b.lo, b.hi) if v is not None]
    span = np.r_[finite, limits] if len(finite) or limits else np.r_[0.0, 1.0]
    lo, hi = float(span.min()), float(span.max())
    pad = 0.08 * (hi - lo) if hi > lo else 1.0
    ylim = (lo - pad, hi + 2 * pad)
    for i, p in enumerate(plants):
        band = bands.get(p)
        if band is not None:
            ax.fill_between([i - 0.42, i + 0.42], band.lo if band.lo is not None else ylim[0],
                            band.hi if band.hi is not None else ylim[1], color="tab:green", alpha=0.18, lw=0)
        group = [(r, v) for r, v in zip(rs, values) if plant_label(r) == p and not np.isnan(v)]
        for k, (r, v) in enumerate(group):
            dx = 0.3 * ((k + 0.5) / len(group) - 0.5) * 2
            band_r = band_for(metric, r.spec.plant, r.spec.variant.get("controller"))
            colour = "0.5" if band_r is None else "tab:green" if band_r.holds(v) else "tab:red"
            y, marker = (v, "D" if r.spec.border else "o") if np.isfinite(v) else (ylim[1] - 0.5 * pad, "^")
            ax.scatter(i + dx, y, c=colour, marker=marker, s=24, edgecolors="k" if r.spec.border else "none",
                       linewidths=0.5, zorder=3)
        fin = [v for _, v in group if np.isfinite(v)]
        if fin:
            ax.plot([i - 0.35, i + 0.35], [np.mean(fin)] * 2, color="k", lw=2, zorder=4)
    ax.set_xticks(range(len(plants)), plants)
    ax.set(xlim=(-0.6, max(len(plants), 1) - 0.4), ylim=ylim)
    ax.grid(alpha=0.3, axis="y")


def render(results: list[CaseResult], outdir) -> list[Path]:
    """The map and the distribution figure of every family among ``results`` into ``outdir``."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    families = [f for f in HEADLINE if any(r.spec.family == f for r in results)]
    paths = []
    for family in families:
        paths.append(map_figure(results, family, outdir / f"validation_{family}.png"))
        paths.append(distribution_figure(results, family, outdir / f"validation_{family}_distribution.png"))
    return paths


def from_sweep(sweep, outdir) -> list[Path]:
    """The figures of an earlier sweep: ``sweep`` is its output directory (its cases.jsonl) or a
    cases.jsonl."""
    sweep = Path(sweep)
    path = sweep / "cases.jsonl" if sweep.is_dir() else sweep
    if not path.is_file():
        raise ValueError(f"--figures: no {path} (a sweep's output directory holds cases.jsonl)")
    results = read_cases(path)
    if not results:
        raise ValueError(f"--figures: {path} holds no case")
    return render(results, outdir)

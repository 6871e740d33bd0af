"""The sweep's report beyond the summary lines (``cdpr validate``, docs/validation.md): the figures
per family drawn from recorded cases (``cdpr validate --figures SWEEP``), and the benchmark area
bench/validation.json (pass rates per family, per robot and plant, the worst case and where).
Cases are recorded by hand (``judge`` on chosen metrics), so that every figure's content is known."""
import importlib.util
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
from matplotlib.collections import PolyCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from cdpr_tools.validate.cases import CaseResult, CaseSpec, judge  # noqa: E402
from cdpr_tools.validate.figures import CRITERIA, render, worst_case  # noqa: E402
from cdpr_tools.validate.report import CaseLog, family_summary  # noqa: E402

SCREEN = (1280, 900)     # px a figure must fit into (as tests/tools/test_figures.py)
ROOT = Path(__file__).resolve().parents[2]


def spec(family, robot, index, x, plant="mismatched", seed=1, border=False, **variant):
    return CaseSpec(family, robot, index, list(x) + [0.0] * (6 - len(x)), border, plant, seed, variant)


@pytest.fixture(scope="module")
def recorded():
    """A small sweep's cases, every family on both robots, both plants; the worst of each known."""
    rs = []
    for robot, s in (("ipanema3", 1.0), ("ipanema3_mini", 0.1)):
        for i, (plant, seed, over) in enumerate((("mismatched", 1, 5.0), ("mismatched", 2, 31.0), ("nominal", 0, 9.0))):
            x = (s * i, -s * i, 0.3 * s * i)
            rs.append(judge(spec("contact", robot, i, x, plant, seed, border=i == 1, fraction=0.3, stiffness=1e5),
                            {"overshoot_percent": over, "settling_s": 1.0, "slack_s": 0.0}, False))
            rs.append(judge(spec("guiding", robot, i, x, plant, seed, direction=(1, 0, 0)),
                            {"rest_wrench_percent": 0.5 * i, "eigenfrequency_error_percent": -1.0 + 1.2 * i}, False))
            rs.append(judge(spec("payload", robot, i, x, plant, seed, fraction=0.5, controller="force_control"),
                            {"estimate_error_percent": 2.0, "sag_cut_percent": 88.0}, False))
        rs.append(CaseResult(spec("payload", robot, 3, (0.2 * s, 0.0, 0.0), fraction=1.0, controller="ik_lc"), {}, {},
                             "refused", "IK-only control does not hold this pose's cables tensed before any payload"))
        rs.append(judge(spec("contact", robot, 4, (-s, s, 0.0), "nominal", 0, fraction=1.0, stiffness=2e6),
                        {"overshoot_percent": float("inf"), "settling_s": float("inf")}, False) if robot == "ipanema3"
                  else judge(spec("contact", robot, 4, (-s, s, 0.0), fraction=1.0, stiffness=2e6),
                             {"overshoot_percent": float("nan")}, True))
        for controller, below in (("force_control", 1.27), ("ik_only", 100.0)):
            rs.append(judge(spec("program", robot, -1, (0, 0, 0), "nominal", 0, border=True, controller=controller,
                                 poses=[[0.5 * s, -s, 0.4 * s]]),
                            {"position_error_max_mm": 9.0, "force_below_f_min_N": below, "force_above_f_max_N": -300.0},
                            False))
    return rs


@pytest.fixture
def saved(monkeypatch):
    """The figures as they are saved: (figure, path) per savefig call."""
    figures = []
    original = Figure.savefig

    def record(fig, path, *args, **kwargs):
        figures.append((fig, Path(path), kwargs.get("dpi", fig.dpi)))
        return original(fig, path, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", record)
    return figures


def texts(fig) -> str:
    return " ".join([fig._suptitle.get_text()] + [ax.get_title() for ax in fig.axes])


def test_worst_case_is_the_farthest_beyond_its_band_and_the_summarys(recorded):
    contact = [r for r in recorded if r.spec.family == "contact"]
    worst = worst_case(contact, "overshoot_percent")
    assert worst.metrics["overshoot_percent"] == float("inf") and worst.spec.robot == "ipanema3"
    mini = [r for r in contact if r.spec.robot == "ipanema3_mini"]
    assert worst_case(mini, "overshoot_percent").metrics["overshoot_percent"] == 31.0     # NaN: not measured
    eigen = [r for r in recorded if r.spec.family == "guiding" and r.spec.robot == "ipanema3"]
    assert worst_case(eigen, "eigenfrequency_error_percent").metrics["eigenfrequency_error_percent"] == pytest.approx(1.4)
    program = [r for r in recorded if r.spec.family == "program"]
    assert {worst_case(program, "force_below_f_min_N").spec.variant["controller"]} == {"force_control"}  # ik_only not judged
    s = family_summary(mini, "contact")["metrics"]["overshoot_percent"]
    assert s["worst"] == 31.0 and "#1" in s["where"]


def test_figures_per_family_name_robot_and_plant_with_units_and_bands(recorded, saved, tmp_path):
    paths = render([r for r in recorded if r.spec.family in ("contact", "payload")], tmp_path)   # (the others: below)
    assert [p.name for p in paths] == [f"validation_{f}{k}.png" for f in ("contact", "payload")
                                       for k in ("", "_distribution")]
    assert all(p.stat().st_size > 10_000 for p in paths)
    for fig, path, dpi in saved:
        width, height = fig.get_size_inches() * dpi
        assert width <= SCREEN[0] and height <= SCREEN[1], (path.name, width, height)
        heading = texts(fig)
        assert "ipanema3_mini" in heading and "ipanema3," in heading or "ipanema3:" in heading, path.name
        assert "nominal" in heading, path.name
        for ax in fig.axes:
            assert ax.get_ylabel().endswith("]"), (path.name, ax.get_ylabel())
        family = path.stem.split("_")[1]
        if path.stem.endswith("_distribution"):
            for ax in fig.axes:                       # the band drawn, one patch per plant, and the plants named
                assert any(isinstance(c, PolyCollection) for c in ax.collections), (path.name, ax.get_title())
                assert {t.get_text() for t in ax.get_xticklabels()} <= {"seed 1", "seed 2", "nominal"}
            assert len(fig.axes) == 2 * len(CRITERIA[family])
        else:
            assert [ax.get_xlabel() for ax in fig.axes] == ["x [m]"] * 4
            assert sorted(ax.get_ylabel() for ax in fig.axes) == ["y [m]", "y [m]", "z [m]", "z [m]"]
    contact = next(fig for fig, path, _ in saved if path.name == "validation_contact.png")
    assert "worst overshoot_percent never settled (out of band): #4" in texts(contact)       # the infinite overshoot, where
    assert "worst overshoot_percent 31 % (out of band): #1" in texts(contact) and "mismatched seed 2" in texts(contact)
    payload = next(fig for fig, path, _ in saved if path.name == "validation_payload.png")
    assert "n/a 1" in texts(payload)                                           # the refused case


def test_the_command_renders_an_earlier_sweeps_figures(recorded, tmp_path, capsys):
    from cdpr_tools.cli import main

    with CaseLog(tmp_path / "sweep") as log:
        log.write([r for r in recorded if r.spec.family == "program"])
    assert main(["validate", "--figures", str(tmp_path / "sweep"), "-o", str(tmp_path / "fig")]) == 0
    assert sorted(p.name for p in (tmp_path / "fig").glob("*.png")) == ["validation_program.png",
                                                                         "validation_program_distribution.png"]
    assert "2 figures" in capsys.readouterr().out
    assert main(["validate", "--figures", str(tmp_path / "none")]) == 1
    assert "--figures" in capsys.readouterr().err


def _bench():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        spec_ = importlib.util.spec_from_file_location("bench_validation", ROOT / "benchmarks" / "bench_validation.py")
        module = importlib.util.module_from_spec(spec_)
        spec_.loader.exec_module(module)
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    return module


def test_bench_area_has_pass_rates_per_family_robot_and_plant_with_the_worst_case(recorded):
    area = _bench().area(recorded, {"command": "c", "wall_s": 1.0, "cpu_s": 1.0}, {"before": 0.5, "after": 0.7}, "r")
    assert (area["cases"], area["applicable"], area["not_applicable"]) == (len(recorded), len(recorded) - 2, 2)
    assert area["passed"] == sum(r.passed for r in recorded)
    assert area["pass_rate_applicable"] == area["passed"] / (len(recorded) - 2)
    contact = area["families"]["contact"]
    # 8 contact cases: overshoot 31 % twice, inf once, one diverged (the Mini's #4): 4 passed
    assert (contact["cases"], contact["passed"], contact["diverged"], contact["pass_rate"]) == (8, 4, 1, 0.5)
    assert contact["criteria"]["overshoot_percent"]["worst"] == float("inf")
    assert contact["criteria"]["overshoot_percent"]["where"].startswith("ipanema3 #4")
    payload = area["families"]["payload"]
    assert (payload["applicable"], payload["not_applicable"], payload["passed"]) == (6, 2, 4)  # sag cut 88: mismatched only
    mini_nominal = area["per_robot_plant"]["ipanema3_mini nominal"]
    assert mini_nominal["program"]["passed"] == 1 and mini_nominal["program"]["pass_rate"] == 0.5
    assert mini_nominal["program"]["criteria"]["force_below_f_min_N"]["worst"] == 1.27
    assert "program to [0.050, -0.100, 0.040], nominal, controller force_control" in \
        mini_nominal["program"]["criteria"]["force_below_f_min_N"]["where"]         # the program's target named
    assert area["per_robot_plant"]["ipanema3 mismatched seed 2"]["contact"]["worst"] == 31.0
    assert (area["python_calibration_us"], area["python_calibration_after_us"]) == (0.5, 0.7)
    assert np.isfinite(area["pass_rate"])


def test_the_program_case_runs_at_the_interpolators_shipped_limits(monkeypatch):
    """The parameter file's gcode_interpreter section over the node's defaults, as the graph's node."""
    from cdpr_control.motion.interpolation import Limits
    from cdpr_tools.validate import cases

    assert cases.shipped_limits("ipanema3_mini").translation.velocity == Limits().translation.velocity
    monkeypatch.setattr(cases, "file_section", lambda robot, node: {"j_max": 5.0} if node == "gcode_interpreter" else {})
    limits = cases.shipped_limits("ipanema3")
    assert limits.translation.jerk == 5.0 and limits.translation.acceleration == Limits().translation.acceleration


def test_the_program_case_says_where_its_lowest_cable_force_was():
    """The note names the lowest cable force's cable, time and platform position: the force is the
    metric's (f_min minus it), the time within the program, the position on its path."""
    import re

    from cdpr_control.model.robot import load_robot
    from cdpr_tools.validate.cases import run_case
    from cdpr_tools.validate.grid import sweep_poses

    robot = load_robot("ipanema3_mini")
    border = [p for p in sweep_poses(robot, 3) if p.border][0]
    (r,) = run_case(CaseSpec("program", "ipanema3_mini", -1, list(robot.home),
                             True, "nominal", 0, {"controller": "force_control", "poses": [border.x[:3].tolist()]}))
    m = re.match(r"lowest cable force (\S+) N \(cable (\d)\) at (\S+) s, platform at \[(.*)\]$", r.note)
    assert m, r.note
    f_min = float(np.max(robot.cable.f_min))
    assert float(m[1]) == pytest.approx(f_min - r.metrics["force_below_f_min_N"], rel=1e-3)
    assert 0.1 <= float(m[3]) <= r.metrics["duration_s"] and 1 <= int(m[2]) <= robot.m
    p, a, b = np.array([float(v) for v in m[4].split(",")]), np.asarray(robot.home[:3]), border.x[:3]
    s = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
    assert np.linalg.norm(p - (a + s * (b - a))) < 0.02            # on the path home -> border -> home


def test_bench_area_from_an_earlier_sweep_takes_its_times_from_its_validation_json(recorded, tmp_path, monkeypatch):
    """benchmarks/bench_validation.py --from-cases: the sweep's wall and CPU time and its identification time
    from the validation.json beside cases.jsonl (the sum of the cases' wall times is not the sweep's)."""
    import json

    bench = _bench()
    monkeypatch.setattr(bench, "OUT", tmp_path / "bench" / "validation.json")
    with CaseLog(tmp_path / "sweep") as log:
        log.write(recorded)
    (tmp_path / "sweep" / "validation.json").write_text(json.dumps(
        {"meta": {"wall_s": 900.0, "cpu_s": 1700.0, "identification_wall_s": 220.0, "jobs": 2}}))
    bench.main(["--from-cases", str(tmp_path / "sweep" / "cases.jsonl")])
    out = json.loads((tmp_path / "bench" / "validation.json").read_text())
    assert (out["sweep_wall_s"], out["sweep_cpu_s"], out["identification_wall_s"], out["jobs"]) == (900.0, 1700.0, 220.0, 2)
    (tmp_path / "sweep" / "validation.json").unlink()             # without it: the cases' own times
    bench.main(["--from-cases", str(tmp_path / "sweep" / "cases.jsonl")])
    out = json.loads((tmp_path / "bench" / "validation.json").read_text())
    assert out["identification_wall_s"] is None and out["sweep_wall_s"] == pytest.approx(sum(r.wall_s for r in recorded))

"""benchmarks/bench_stages_against.py: the renamed copies are the tree's own code and nothing else
(a copy that still imported the original package would compare a tree with itself), and the
summary is the median over the runs of each figure and of the ratio."""
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
import bench_stages_against  # noqa: E402


def test_the_copies_import_only_themselves(tmp_path):
    bench_stages_against.renamed_copy(ROOT, "this", tmp_path)
    sources = list((tmp_path / "cdpr_control_this").rglob("*.py")) + list((tmp_path / "cdpr_sim_this").rglob("*.py")) \
        + [tmp_path / "bench_this.py"]
    left = [str(p) for p in sources
            if any(line.lstrip().startswith(("import cdpr_control", "from cdpr_control ", "from cdpr_control.",
                                             "import cdpr_sim", "from cdpr_sim ", "from cdpr_sim."))
                   for line in p.read_text(encoding="utf-8").splitlines())]
    assert not left, f"copies that still import the original packages: {left}"
    # the copied benchmark and its stages import without the original packages (none on the path)
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import bench_this; "
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('cdpr_control', 'cdpr_sim')); "
            "assert not bad, bad; print(bench_this.ControlLoop.__module__)")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, timeout=300,
                         env={"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "NUMBA_CACHE_DIR": str(tmp_path / "numba")})
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "cdpr_control_this.control.loop"


def test_the_summary_is_the_median_over_the_runs():
    def run(this, other):
        return {"this": {"stages_us": {"fk_us": this}, "controller_us": 2 * this},
                "other": {"stages_us": {"fk_us": other}, "controller_us": 2 * other}}
    s = bench_stages_against.summary([run(10.0, 10.0), run(12.0, 10.0), run(9.0, 10.0)])
    assert s["fk_us"] == {"this_us": 10.0, "other_us": 10.0, "ratio": 1.0}
    assert s["controller"]["this_us"] == 20.0 and s["controller"]["ratio"] == pytest.approx(1.0)
    s = bench_stages_against.summary([run(11.0, 10.0), run(12.0, 10.0)])
    assert s["fk_us"]["ratio"] == pytest.approx(1.15)

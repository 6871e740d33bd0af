"""The reproduction of Tables 3.2 and 3.3 (coarse grid to stay fast)."""
import json

import numpy as np
import pytest

from cdpr_control.analysis import force_distribution_comparison as cmp


@pytest.fixture(scope="module")
def comparison():
    return cmp.compare_force_distributions(step=0.75, masses=(30.0, 150.0))


def test_table_3_2_rows_and_relations(comparison):
    rows = {(r.method, r.workspace): r for r in comparison.table_3_2}
    assert set(rows) == set(cmp.THESIS_TABLE_3_2)
    for r in rows.values():
        assert r.poses > 0 and np.isfinite([r.mean_force, r.xi_M, r.xi_RMS, r.xi_RMS_cable]).all()
        assert r.xi_RMS_cable >= r.xi_RMS                # sqrt(m) times the vector RMS / m
    # "QP_med delivers almost the same tension level and smoothness as the ACF"
    for s in ("W_CF", "W_ACF"):
        acf = rows[("ACF/CF" if s == "W_CF" else "ACF", s)]
        med = rows[("QP_med", s)]
        assert med.mean_force == pytest.approx(acf.mean_force, rel=0.01)
        assert med.xi_M == pytest.approx(acf.xi_M, rel=0.05)
    for s in ("W_CF", "W_ACF", "W_ACF\\W_CF"):
        levels = [rows[(q, s)].mean_force for q in ("QP_min", "QP_med", "QP_max")]
        assert levels == sorted(levels) and levels[0] < levels[2]
    assert comparison.W_CF < comparison.W_ACF <= comparison.W_QP
    assert 0.4 < comparison.cf_share < 0.9                # thesis: 57.5 %


def test_table_3_3_has_the_thesis_trend(comparison):
    light, heavy = comparison.table_3_3
    for row in (light, heavy):
        assert row.qp_min < row.acf < row.qp_max
    assert light.poses > heavy.poses                      # the workspace shrinks with the load
    assert light.delta_min < heavy.delta_min < 0.0        # minimisation helps most when light
    assert light.delta_min == pytest.approx(-56.1, abs=8.0)


def test_command_line_prints_tables_and_writes_json(tmp_path, capsys):
    out = tmp_path / "cmp.json"
    assert cmp.main(["--step", "1.0", "--masses", "30", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Table 3.2" in text and "Table 3.3" in text and "QP_min" in text
    data = json.loads(out.read_text())
    assert data["W_ACF"] > 0 and len(data["table_3_2"]) == len(cmp.THESIS_TABLE_3_2)
    assert "delta_min_percent" in data["table_3_3"][0]

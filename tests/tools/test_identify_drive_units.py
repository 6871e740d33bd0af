"""`cdpr identify drive` prints every identified time constant with its unit (issue 27)."""
import re

import pytest

from cdpr_tools import cli
from cdpr_tools.identify import experiments


@pytest.mark.parametrize("robot, model, seconds", [("ipanema3", "pt1_deadtime", ("T_1", "T_d")),
                                                   ("ipanema3_mini", "second_order", ("T_w", "T_d"))])
def test_drive_parameters_are_printed_with_their_units(tmp_path, capsys, robot, model, seconds):
    bag = experiments.record_drive_sweep(tmp_path / "sweep", robot, duration=0.3, seed=5)
    assert cli.main(["identify", "drive", str(bag), "--model", model]) == 0
    out = capsys.readouterr().out
    number = r"-?[0-9.]+(?:e[+-]?[0-9]+)?"
    for name in seconds:
        assert re.search(rf"\b{name} = {number} s\b", out), out
    if model == "second_order":
        assert re.search(rf"\bzeta = {number}(,|  )", out), out

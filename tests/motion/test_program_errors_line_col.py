"""Programs the planner or the parser cannot take are refused with their line:col (issues 27, 28):
a tension level outside 0..1 (3.27), time laws ruckig cannot plan, bytes that are not UTF-8."""
import pytest

from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.program import GCodeError
from cdpr_control.motion.program_check import check_program
from cdpr_control.model.robot import load_robot


def diagnostics(source, robot=None):
    with pytest.raises(GCodeError) as err:
        program = parse_gcode(source, start_pose=None if robot is None else robot.home)
        check_program(program, robot)
    return err.value.diagnostics


@pytest.mark.parametrize("level", ["2", "-0.1", "1.0001"])
def test_tension_level_outside_zero_to_one_is_refused_at_its_p_word(level):
    d, = diagnostics(f"G90\nM100 P{level}")
    assert (d.line, d.column, d.text) == (2, 6, f"P{level}")
    assert "P must be in [0, 1]" in d.message


@pytest.mark.parametrize("level", [0.0, 0.5, 1.0])
def test_tension_levels_within_zero_to_one_are_taken(level):
    block, = parse_gcode(f"M100 P{level}").blocks
    assert block.value == level


@pytest.mark.parametrize("source, line", [("G18\nG2 Z0 X0 K0.01 P1 F0.001\n", 2),   # a 3770 s full turn
                                          ("G20 G1 X0.0000001 F0.001\n", 1)])        # 2.5 nm at a crawl
def test_time_laws_ruckig_cannot_plan_name_their_line(source, line):
    d, = diagnostics(source, load_robot("ipanema3_mini"))
    assert d.line == line
    assert d.message.startswith("the time law cannot be planned at this feed (ruckig: error in step 2")
    assert "inp." not in d.message and "\n" not in d.message   # ruckig's dump of its input is left out


@pytest.mark.parametrize("data, line, column, text", [
    ("G1 X0.01 F600 ; café\n".encode("latin-1"), 1, 20, "byte 0xe9"),
    ("G1 X0\nG1 X1".encode("utf-16"), 1, 1, "byte 0xff"),
    (b"G1 X0\n\x80\x81", 2, 1, "byte 0x80"),
])
def test_bytes_that_are_not_utf8_are_named_with_line_and_column(data, line, column, text):
    d, = diagnostics(data)
    assert (d.line, d.column, d.text) == (line, column, text)
    assert d.message.startswith("not UTF-8 text")

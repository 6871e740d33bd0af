"""Parser of the G-code dialect (docs/gcode.md): units, modes, arcs, parameters and diagnostics."""
import math

import numpy as np
import pytest

from cdpr_control.motion.gcode import ARC_RADIUS_TOLERANCE, PARAMETER_MCODES, parse_gcode
from cdpr_control.motion.path import ArcSegment, LineSegment
from cdpr_control.motion.program import Dwell, GCodeError, Motion, ParameterCommand, ProgramStop


def motions(program):
    return [b for b in program.blocks if isinstance(b, Motion)]


def errors(text):
    with pytest.raises(GCodeError) as info:
        parse_gcode(text)
    return info.value.diagnostics


def test_units_are_converted_to_si():
    p = parse_gcode("G21 G1 X100 Y-20 Z0.5 F6000\nG20 X1 A90 U5 V-2 W3.5")
    a, b = motions(p)
    np.testing.assert_allclose(a.segment.q1[:3], [0.1, -0.02, 0.0005])
    assert a.feed == pytest.approx(0.1)  # 6000 mm/min = 0.1 m/s
    np.testing.assert_allclose(b.segment.q1, [0.0254, -0.02, 0.0005, math.pi / 2, 0, 0, 5, -2, 3.5])
    assert b.feed == pytest.approx(6000 * 0.0254 / 60)  # F is in the current units: in/min
    np.testing.assert_allclose(p.end_pose, b.segment.q1[:6])
    np.testing.assert_allclose(p.end_force, [5, -2, 3.5])


def test_rotation_only_feed_is_degrees_per_minute_and_force_only_has_none():
    p = parse_gcode("G1 A30 F600\nW-50")
    rot, force = motions(p)
    assert rot.segment.metric == 1 and rot.feed == pytest.approx(math.radians(10))
    assert force.segment.metric == 2 and force.feed is None
    assert force.segment.length == pytest.approx(50)


def test_modal_motion_incremental_mode_and_start_pose():
    start = [0.01, 0.02, 0.03, 0.1, 0.2, 0.3]
    p = parse_gcode("N10 G91 G1 X5 F100 (rel)\nN20 Y5 ; also relative\n%\nG90 Z0", start_pose=start, start_force=[1, 2, 3])
    a, b, c = motions(p)
    np.testing.assert_allclose(a.segment.q1[:6], [0.015, 0.02, 0.03, 0.1, 0.2, 0.3])
    np.testing.assert_allclose(b.segment.q1[:3], [0.015, 0.025, 0.03])
    np.testing.assert_allclose(c.segment.q1[:3], [0.015, 0.025, 0.0])
    np.testing.assert_allclose(c.segment.q1[6:], [1, 2, 3])
    assert [m.line for m in (a, b, c)] == [1, 2, 4]


def test_rapid_has_no_feed_and_needs_none():
    (m,) = motions(parse_gcode("G0 X10"))
    assert m.rapid and m.feed is None and isinstance(m.segment, LineSegment)


def test_move_below_min_travel_is_dropped():
    p = parse_gcode("G1 X0.0000001 F100")  # 1e-10 m
    assert motions(p) == [] and np.all(p.end == 0)


def test_arc_by_centre_g17_quarter_circle():
    p = parse_gcode("G1 X10 F100\nG3 X0 Y10 I-10 J0")
    arc = motions(p)[1].segment
    assert isinstance(arc, ArcSegment)
    assert arc.sweep == pytest.approx(math.pi / 2)
    assert arc.length == pytest.approx(0.01 * math.pi / 2)
    q, dq, ddq = arc.at(arc.length / 2)
    np.testing.assert_allclose(q[:3], [0.01 * math.sqrt(0.5), 0.01 * math.sqrt(0.5), 0], atol=1e-15)
    assert np.linalg.norm(dq[:3]) == pytest.approx(1.0)  # s is the arc length
    np.testing.assert_allclose(ddq[:3], -q[:3] / 0.01**2, rtol=1e-12)  # centripetal, curvature 1/r


@pytest.mark.parametrize("plane, code, start, end, offsets, mid", [
    # G18: plane z-x, G2 is clockwise seen from +y: from +x towards +z
    ("G18", "G2", "X10 Z0", "X-10 Z0", "I-10", [0, 0, 0.01]),
    ("G18", "G3", "X10 Z0", "X-10 Z0", "I-10", [0, 0, -0.01]),
    # G19: plane y-z, G3 counter-clockwise seen from +x: from +y towards +z
    ("G19", "G3", "Y10 Z0", "Y-10 Z0", "J-10", [0, 0, 0.01]),
    ("G17", "G2", "X10 Y0", "X-10 Y0", "I-10", [0, -0.01, 0]),
])
def test_arc_planes_and_directions(plane, code, start, end, offsets, mid):
    p = parse_gcode(f"G1 {start} F100\n{plane} {code} {end} {offsets}")
    arc = motions(p)[1].segment
    np.testing.assert_allclose(arc.at(arc.length / 2)[0][:3], mid, atol=1e-15)


def test_arc_by_radius_short_and_long_way():
    short = motions(parse_gcode("G1 X10 F100\nG3 X0 Y10 R10"))[1].segment
    long_ = motions(parse_gcode("G1 X10 F100\nG3 X0 Y10 R-10"))[1].segment
    assert short.sweep == pytest.approx(math.pi / 2)
    assert long_.sweep == pytest.approx(3 * math.pi / 2)
    np.testing.assert_allclose(short.centre, [0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(long_.centre, [0.01, 0.01, 0], atol=1e-15)


def test_full_circle_turns_and_helix():
    arc = motions(parse_gcode("G1 X10 F100\nG2 X10 Y0 Z6 I-10 P3"))[1].segment
    assert arc.sweep == pytest.approx(-6 * math.pi)
    assert arc.length == pytest.approx(math.hypot(0.01 * 6 * math.pi, 0.006))
    q, _, _ = arc.at(arc.length / 3)  # one turn: back at the start angle, a third of the height up
    np.testing.assert_allclose(q[:3], [0.01, 0, 0.002], atol=1e-15)


def test_dwell_stops_and_end_of_program():
    p = parse_gcode("G4 P0.25\nM0\nM1\nM30\nthis line is not read Q")
    assert p.blocks == (Dwell(0.25, 1), ProgramStop(False, 2), ProgramStop(True, 3))


def test_parameter_mcodes_and_assignments():
    p = parse_gcode('M100 P0.5\nM101\nN5 #<cable_force_controller.f_ref> = 80.0\n'
                    '#/cdpr/ospc.gains.kp = 3 (int)\n#<x.flag> = TRUE\n#<x.label> = "a b"')
    node, name, _ = PARAMETER_MCODES[100]
    assert p.blocks == (
        ParameterCommand(node, name, 0.5, 1),
        ParameterCommand(*PARAMETER_MCODES[101], 2),
        ParameterCommand("cable_force_controller", "f_ref", 80.0, 3),
        ParameterCommand("/cdpr/ospc", "gains.kp", 3, 4),
        ParameterCommand("x", "flag", True, 5),
        ParameterCommand("x", "label", "a b", 6),
    )
    assert isinstance(p.blocks[3].value, int) and isinstance(p.blocks[2].value, float)


@pytest.mark.parametrize("text, line, column, offending, message", [
    ("G1 X10", 1, 1, "G1", "no feed rate"),
    ("G1 X1 F100\nG1 Q5", 2, 4, "Q5", "unsupported word Q"),
    ("X10", 1, 1, "X10", "no motion mode"),
    ("G1 F100 X1 X2", 1, 12, "X2", "given twice"),
    ("G1 G0 X1", 1, 4, "G0", "motion group"),
    ("G7", 1, 1, "G7", "unsupported G-code"),
    ("G1.5", 1, 1, "G1.5", "unsupported G-code"),
    ("M3", 1, 1, "M3", "unsupported M-code"),
    ("M0 M1", 1, 4, "M1", "one M-code"),
    ("G2 X10 Y0 F100", 1, 1, "G2", "centre offsets"),
    ("G2 X10 Y0 I3 F100", 1, 1, "G2", "not on the arc"),
    ("G2 X10 R2 F100", 1, 8, "R2", "smaller than half"),
    ("G2 X10 I5 R5 F100", 1, 8, "I5", "either R"),
    ("G2 X10 Y0 I5 K1 F100", 1, 14, "K1", "no centre offset"),
    ("G1 X1 I5 F100", 1, 7, "I5", "no effect"),
    ("G1 X1 (unclosed", 1, 7, "(unclosed", "not closed"),
    ("G1 X1..2", 1, 7, ".", "unexpected character"),
    ("G1 X", 1, 4, "X", "needs a number"),
    ("G4", 1, 1, "G4", "dwell time"),
    ("G4 P-1", 1, 4, "P-1", "must not be negative"),
    ("G4 X1 P1", 1, 1, "G4", "combined"),
    ("G1 X1 F0", 1, 7, "F0", "positive"),
    ("G1 F100 X" + "9" * 400, 1, 9, "X" + "9" * 400, "out of range"),
    ("G1 X1 F100 N5", 1, 12, "N5", "first word"),
    ("#foo = 1", 1, 2, "foo", "node.parameter"),
    ("#<a.b> 1", 1, 8, "1", "expected '='"),
    ("#<a.b> = x", 1, 10, "x", "expected a number"),
    ("G1 #<a.b> = 1", 1, 4, "#<a.b> = 1", "stand alone"),
    ("#<a.b> = 1 G1", 1, 12, "G1", "nothing may follow"),
    ("M100", 1, 1, "M100", "needs the value P"),
    ("M101 P1", 1, 6, "P1", "no effect"),
    ("G1 X1 F100\nG2 X1 Y0 I0.000001", 2, 1, "G2", "radius must exceed"),
    ("G1 X10 F100\nG2 X10 Y0 I-10 P1.5", 2, 16, "P1.5", "positive integer"),
    ("G1 F100 X1\u00e9", 1, 11, "\u00e9", "unexpected character"),
])
def test_errors_have_line_column_and_offending_text(text, line, column, offending, message):
    (d,) = errors(text)
    assert (d.line, d.column, d.text) == (line, column, offending)
    assert message in d.message
    assert str(d).startswith(f"{line}:{column}: ")


def test_every_error_is_reported_and_a_bad_line_changes_no_state():
    diags = errors("G1 X1 F100\nQ1\nG91 G7\nX2 Y3 Y4\nG1 X5")
    assert [(d.line, d.column) for d in diags] == [(2, 1), (3, 5), (4, 7)]
    p = parse_gcode("G1 X1 F100\nG91 X1\nX1")  # sanity: G91 does act when its line is good
    np.testing.assert_allclose(p.end[:3], [0.003, 0, 0])


def test_arc_radius_tolerance_accepts_rounded_end_points():
    ok = f"G1 X10 F100\nG3 X0 Y{10 + 0.9 * ARC_RADIUS_TOLERANCE * 1e3} I-10"
    arc = motions(parse_gcode(ok))[1].segment
    np.testing.assert_allclose(arc.at(arc.length)[0][:3], [0, 0.01 + 0.9 * ARC_RADIUS_TOLERANCE, 0], atol=1e-15)
    errors(f"G1 X10 F100\nG3 X0 Y{10 + 1.1 * ARC_RADIUS_TOLERANCE * 1e3} I-10")


def test_non_text_and_bad_utf8_are_diagnosed():
    (d,) = errors(b"G1 X1 F100\nG1 Y\xff")
    assert (d.line, d.column) == (2, 5)
    (d,) = errors(None)
    assert (d.line, d.column) == (1, 1)
    assert motions(parse_gcode(b"G0 X1"))[0].segment.q1[0] == pytest.approx(0.001)


def test_a_utf8_byte_order_mark_is_not_part_of_the_program():
    """Windows editors save UTF-8 with a byte order mark; it was read as an unexpected character at 1:1."""
    with_bom = parse_gcode("G1 X1 F100".encode("utf-8-sig"))
    assert motions(with_bom)[0].segment.q1[0] == pytest.approx(motions(parse_gcode(b"G1 X1 F100"))[0].segment.q1[0])
    (d,) = errors(b"\xef\xbb\xbfG1 X1 F100\nG1 Y\xff")                 # line:col still count from the text
    assert (d.line, d.column) == (2, 5)

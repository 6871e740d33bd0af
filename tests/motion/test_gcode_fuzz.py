"""Property-based tests: on any input the parser and planner return a planned Program or a
GCodeError with line:col, and whatever parses interpolates within the limits to its end point."""
import os
import re

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cdpr_control import programs
from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.program import GCodeError, Program
from cdpr_control.motion.interpolation import AxisLimits, Interpolator, Limits, sample_program

# 3200 parser examples in all, in well under 30 s.
FAST = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow], database=None)
# CDPR_FUZZ_SCALE=31 runs about 100,000 programs (a nightly run); 1 (make test) about 3,300
SCALE = max(1, int(os.environ.get("CDPR_FUZZ_SCALE", "1")))
GCODE_ALPHABET = "GMXYZABCUVWIJKRFNPgx0123456789.-+ \t()#;<>=\"%\n\r_/" + "Qe\u00e9\x00\u2028"
CORPUS = [programs.read(name) for name in programs.names()] + [
    "G21 G90 G1 X10 Y5 F3000\nG2 X20 Y5 R5\nG3 X10 Y5 I-5 J0\nG4 P0.1\nM100 P80\n#<a.b> = 1\nM2",
    "G20 G91 G0 X1\nG18 G2 X1 Z1 I0.5 K0.5\nG19 G3 Y1 Z0 J0.5 K-0.5 F10\nM0\nM30",
]


def check_parse(text, plan=True):
    """The contract of parse_gcode and of planning: a Program with a planned time law, or
    GCodeError whose diagnostics point into the text; no other exception."""
    try:
        program = parse_gcode(text)
        if plan:
            Interpolator(program, FAST_LIMITS)
    except GCodeError as err:
        assert err.diagnostics
        lines = text.split("\n")
        for d in err.diagnostics:
            assert 1 <= d.line <= len(lines)
            assert 1 <= d.column <= len(lines[d.line - 1]) + 1
            assert d.text and d.message
            assert re.match(rf"{d.line}:{d.column}: ", str(d))
        return None
    assert isinstance(program, Program)
    assert np.all(np.isfinite(program.end))
    return program


@settings(FAST, max_examples=1500 * SCALE)
@given(st.text(alphabet=GCODE_ALPHABET, max_size=120))
def test_random_text(text):
    check_parse(text)


@settings(FAST, max_examples=200 * SCALE)
@given(st.text(max_size=60))
def test_arbitrary_unicode(text):
    check_parse(text)


@st.composite
def mutated(draw):
    text = draw(st.sampled_from(CORPUS))
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(text)))
        op = draw(st.sampled_from(["insert", "delete", "replace", "dup_line", "swap_lines", "truncate"]))
        if op == "insert":
            text = text[:i] + draw(st.text(alphabet=GCODE_ALPHABET, min_size=1, max_size=4)) + text[i:]
        elif op == "delete":
            text = text[:i] + text[i + draw(st.integers(1, 5)):]
        elif op == "replace":
            text = text[:i] + draw(st.sampled_from(GCODE_ALPHABET)) + text[i + 1:]
        elif op == "truncate":
            text = text[:i]
        else:
            lines = text.split("\n")
            a, b = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
            if op == "dup_line":
                lines.insert(a, lines[b])
            else:
                lines[a], lines[b] = lines[b], lines[a]
            text = "\n".join(lines)
    return text


@settings(FAST, max_examples=1500 * SCALE)
@given(mutated())
def test_mutated_programs(text):
    check_parse(text)


NUMBER = st.floats(-60, 60, allow_nan=False).map(lambda v: f"{v:.3f}")
WORDS = st.lists(st.tuples(st.sampled_from("XYZABCUVW"), NUMBER), min_size=1, max_size=4,
                 unique_by=lambda w: w[0]).map(lambda ws: " ".join("".join(w) for w in ws))
PLANE_LETTERS = {"G17": ("XY", "IJ", "Z"), "G18": ("ZX", "KI", "Y"), "G19": ("YZ", "JK", "X")}


@st.composite
def arc_block(draw):
    """An incremental arc whose end point lies on the circle (up to the 1 um rounding)."""
    plane = draw(st.sampled_from(sorted(PLANE_LETTERS)))
    (a, b), (i, j), normal = PLANE_LETTERS[plane]
    radius = draw(st.floats(1.0, 50.0))
    beta, gamma = draw(st.floats(0, 6.283)), draw(st.floats(0, 6.283))
    ci, cj = -radius * np.cos(beta), -radius * np.sin(beta)  # centre relative to the start
    end = (ci + radius * np.cos(gamma), cj + radius * np.sin(gamma))
    extra = draw(st.lists(st.sampled_from([normal, "A", "U", "W"]), max_size=2, unique=True))
    words = f"{a}{end[0]:.3f} {b}{end[1]:.3f} {i}{ci:.3f} {j}{cj:.3f} " + " ".join(c + draw(NUMBER) for c in extra)
    turns = draw(st.sampled_from(["", " P2"]))
    return f"G91 {plane} {draw(st.sampled_from(['G2', 'G3']))} {words}{turns}"


@st.composite
def structured_program(draw):
    """Mostly valid programs: lines, arcs by centre or R, dwells, stops, in any plane and mode."""
    lines = ["G21 F6000"]
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(["G0", "G1", "arc", "R", "G4", "M0", "G90", "G91", "M101"]))
        if kind in ("G0", "G1"):
            lines.append(f"{kind} {draw(WORDS)}")
        elif kind == "arc":
            lines.append(draw(arc_block()))
        elif kind == "R":
            lines.append(f"G90 G17 G{draw(st.sampled_from('23'))} X{draw(NUMBER)} Y{draw(NUMBER)} "
                         f"R{draw(st.sampled_from(['', '-']))}{draw(st.floats(90, 200)):.3f}")
        elif kind == "G4":
            lines.append(f"G4 P{draw(st.floats(0, 0.05)):.3f}")
        else:
            lines.append(kind)
    return "\n".join(lines)


FAST_LIMITS = Limits(AxisLimits(2.0, 20.0, 400.0), AxisLimits(10.0, 100.0, 2000.0), AxisLimits(1e3, 1e4, 1e6))


@settings(FAST, max_examples=60 * SCALE)
@given(structured_program())
def test_structured_programs_parse_and_interpolate_within_limits(text):
    program = check_parse(text)
    if program is None:
        return
    dt = 1e-3
    s = sample_program(program, FAST_LIMITS, dt)
    tol = 1e-9
    for cols, lim in ((slice(0, 3), FAST_LIMITS.translation), (slice(3, 6), FAST_LIMITS.rotation)):
        assert np.all(np.linalg.norm(np.diff(s.x[:, cols], axis=0), axis=1) <= lim.velocity * dt * (1 + tol) + 1e-12)
        assert np.all(np.linalg.norm(s.xd[:, cols], axis=1) <= lim.velocity * (1 + tol))
        assert np.all(np.linalg.norm(s.xdd[:, cols], axis=1) <= lim.acceleration * (1 + tol))
        assert np.all(np.linalg.norm(np.diff(s.xdd[:, cols], axis=0), axis=1) <= lim.jerk * dt * (1 + 1e-6))
    np.testing.assert_array_equal(s.x[-1], program.end_pose)
    np.testing.assert_array_equal(s.force[-1], program.end_force)


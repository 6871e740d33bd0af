"""Parser of the cdpr G-code dialect (docs/gcode.md; thesis sections 2.3.2 and 5.1.2).

parse_gcode(text) -> Program, or GCodeError listing every error with line, column and the
offending text. No other exception escapes for any text. Values are converted to SI on the way:
X Y Z I J K R in mm (G21) or inch (G20) -> m, A B C in degrees -> rad, U V W in N, F per minute
-> per second, G4 P in seconds.
"""

from __future__ import annotations

import math
import re
import string
from dataclasses import dataclass

import numpy as np

from cdpr_control.motion.path import MIN_TRAVEL, ArcSegment, LineSegment, travel_metric
from cdpr_control.motion.program import (Block, Diagnostic, Dwell, GCodeError, Motion, ParameterCommand,
    Program, ProgramStop)

#: Largest magnitude of any number in a program; keeps the geometry far from overflow.
MAX_ABS_VALUE = 1e6
#: An arc end point may be off the circle by this much (m) to allow for rounded coordinates.
ARC_RADIUS_TOLERANCE = 5e-6
MM = 1e-3
INCH = 25.4e-3

#: Parameter-setting M-codes: code -> (node, parameter, value); value None means "the P word".
PARAMETER_MCODES: dict[int, tuple[str, str, bool | None]] = {
    100: ("force_distribution", "tension_level", None),
    101: ("cable_force_controller", "enabled", True),
    102: ("cable_force_controller", "enabled", False),
    103: ("hybrid_force_controller", "enabled", True),
    104: ("hybrid_force_controller", "enabled", False),
}
#: Range of the P word of parameter-setting M-codes: the tension level of (3.27) is 0 (f_min) .. 1 (f_max).
PARAMETER_MCODE_RANGES: dict[int, tuple[float, float]] = {100: (0.0, 1.0)}
_STOP_MCODES = {0, 1, 2, 30}

_AXES = "XYZABCUVW"  # letter -> index in the path vector q
_ARC_WORDS = "IJKR"
_OTHER_WORDS = "FNP"
_G_GROUPS = {0: "motion", 1: "motion", 2: "motion", 3: "motion", 4: "dwell", 17: "plane", 18: "plane",
             19: "plane", 20: "units", 21: "units", 90: "distance", 91: "distance", 94: "feed mode"}
# plane -> (first, second, normal axis index), centre-offset letters, letter that is no offset there
_PLANES = {17: ((0, 1, 2), "IJ", "K"), 18: ((2, 0, 1), "KI", "J"), 19: ((1, 2, 0), "JK", "I")}

_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)")
_NAME = re.compile(r"<([^<>]*)>|([A-Za-z_/][A-Za-z0-9_./]*)")
_NODE = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(?:/[A-Za-z_][A-Za-z0-9_]*)*")
_PARAMETER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*")
_BOOL = re.compile(r"(true|false)(?![A-Za-z0-9_])", re.IGNORECASE)
_STRING = re.compile(r'"([^"]*)"')


@dataclass(frozen=True)
class _Word:
    letter: str
    value: float
    column: int
    text: str


@dataclass(frozen=True)
class _Assignment:
    node: str
    parameter: str
    value: bool | int | float | str
    column: int
    text: str


class _LineError(Exception):
    """Internal: aborts the current line; turned into a Diagnostic by the parser."""

    def __init__(self, column: int, text: str, message: str):
        super().__init__(message)
        self.column, self.text, self.message = column, text or "<end of line>", message


def _skip_space(line: str, i: int) -> int:
    while i < len(line) and line[i] in " \t":
        i += 1
    return i


def _lex_assignment(line: str, i: int) -> tuple[_Assignment, int]:
    """`#<node.param> = value` or `#node.param = value` starting at the '#' at index i."""
    j = _skip_space(line, i + 1)
    name_match = _NAME.match(line, j)
    if not name_match:
        raise _LineError(i + 1, line[i:j + 1], "expected a parameter name <node.parameter> after #")
    name = name_match.group(1) if name_match.group(1) is not None else name_match.group(2)
    node, dot, parameter = name.partition(".")
    if not dot or not _NODE.fullmatch(node) or not _PARAMETER.fullmatch(parameter):
        raise _LineError(j + 1, name_match.group(0), "parameter name must be node.parameter (ROS names)")
    k = _skip_space(line, name_match.end())
    if k >= len(line) or line[k] != "=":
        raise _LineError(k + 1, line[k:k + 1], "expected '=' after the parameter name")
    k = _skip_space(line, k + 1)
    value: bool | int | float | str
    if m := _STRING.match(line, k):
        value = m.group(1)
    elif m := _BOOL.match(line, k):
        value = m.group(1).lower() == "true"
    elif m := _NUMBER.match(line, k):
        number = float(m.group())
        if not abs(number) <= MAX_ABS_VALUE:
            raise _LineError(k + 1, m.group(), f"value out of range (|value| <= {MAX_ABS_VALUE:g})")
        value = number if "." in m.group() else int(m.group())
    else:
        raise _LineError(k + 1, line[k:k + 1], "expected a number, true, false or a \"string\"")
    return _Assignment(node, parameter, value, i + 1, line[i:m.end()]), m.end()


def _lex(line: str) -> tuple[list[_Word], _Assignment | None]:
    """Split one line into words (letter + number) and an optional assignment; drop comments."""
    words: list[_Word] = []
    assignment = None
    if line.strip(" \t") == "%":  # program delimiter line of many G-code files
        return words, None
    i = 0
    while i < len(line):
        ch = line[i]
        if ch in " \t":
            i += 1
        elif ch == ";":
            break
        elif ch == "(":
            end = line.find(")", i)
            if end < 0:
                raise _LineError(i + 1, line[i:], "comment is not closed with ')'")
            i = end + 1
        elif assignment is not None:
            raise _LineError(i + 1, line[i:], "nothing may follow an assignment in its block")
        elif ch == "#":
            if any(w.letter != "N" for w in words):
                raise _LineError(i + 1, line[i:], "an assignment must stand alone in its block")
            assignment, i = _lex_assignment(line, i)
        elif ch in string.ascii_letters:
            j = _skip_space(line, i + 1)
            number = _NUMBER.match(line, j)
            if not number:
                raise _LineError(i + 1, line[i:j + 1], f"word {ch.upper()} needs a number")
            words.append(_Word(ch.upper(), float(number.group()), i + 1, line[i:number.end()]))
            i = number.end()
        else:
            raise _LineError(i + 1, ch, "unexpected character")
    return words, assignment


def _integer(word: _Word) -> int:
    if not word.value.is_integer():
        raise _LineError(word.column, word.text, f"{word.letter} needs an integer")
    return int(word.value)


class _Parser:
    """Modal state of the interpreter and the blocks produced so far."""

    def __init__(self, start: np.ndarray):
        self.q = start.copy()
        self.motion: int | None = None
        self.plane = 17
        self.scale = MM
        self.absolute = True
        self.feed: float | None = None  # as programmed, per minute
        self.ended = False
        self.blocks: list[Block] = []

    def line(self, lineno: int, text: str) -> None:
        words, assignment = _lex(text)
        for word in words:
            if not abs(word.value) <= MAX_ABS_VALUE:
                raise _LineError(word.column, word.text, f"value out of range (|value| <= {MAX_ABS_VALUE:g})")
        words = self._strip_line_number(words)
        if assignment is not None:
            self.blocks.append(ParameterCommand(assignment.node, assignment.parameter, assignment.value, lineno))
            return
        g, m, other = self._classify(words)
        # Modal settings are applied to a copy so that a bad line leaves the state untouched.
        plane = _integer(g["plane"]) if "plane" in g else self.plane
        scale = (INCH if _integer(g["units"]) == 20 else MM) if "units" in g else self.scale
        absolute = _integer(g["distance"]) == 90 if "distance" in g else self.absolute
        feed = self.feed
        if "F" in other:
            if other["F"].value <= 0.0:
                raise _LineError(other["F"].column, other["F"].text, "feed rate F must be positive")
            feed = other["F"].value
        motion = _integer(g["motion"]) if "motion" in g else self.motion
        used = {"F", "N"}
        blocks: list[Block] = []
        axis_words = [other[a] for a in _AXES if a in other]
        if "dwell" in g:
            if axis_words or "motion" in g:
                raise _LineError(g["dwell"].column, g["dwell"].text, "G4 cannot be combined with a motion")
            blocks.append(self._dwell(g["dwell"], other.get("P"), lineno))
            used.add("P")
        q_end = self.q
        if axis_words:
            if motion is None:
                raise _LineError(axis_words[0].column, axis_words[0].text,
                                 "no motion mode: program G0, G1, G2 or G3 first")
            q_end = self._target(axis_words, scale, absolute)
            lead = g.get("motion", axis_words[0])
            if motion != 0 and feed is None:
                raise _LineError(lead.column, lead.text, "no feed rate F programmed for this motion")
            if motion in (2, 3):
                segment = self._arc(q_end, plane, motion == 2, other, scale, lead)
                used.update(_ARC_WORDS + "P")
            else:
                metric = travel_metric(q_end - self.q)
                segment = None if metric is None else LineSegment(self.q, q_end, metric)
            if segment is None:
                q_end = self.q  # a move shorter than MIN_TRAVEL is dropped; the platform stays put
            else:
                blocks.append(Motion(segment, _feed_si(feed, scale, segment.metric, motion), motion == 0, lineno))
        if m is not None:
            blocks.extend(self._mcode(m, None if "P" in used else other.get("P"), lineno))
            used.add("P")
        for letter, word in other.items():
            if letter not in used and letter not in _AXES:
                raise _LineError(word.column, word.text, f"{letter} has no effect in this block")
        self.plane, self.scale, self.absolute, self.feed, self.motion = plane, scale, absolute, feed, motion
        self.q = q_end
        self.blocks.extend(blocks)
        if m is not None and _integer(m) in (2, 30):
            self.ended = True

    @staticmethod
    def _strip_line_number(words: list[_Word]) -> list[_Word]:
        for k, word in enumerate(words):
            if word.letter == "N":
                if k != 0:
                    raise _LineError(word.column, word.text, "line number N must be the first word")
                if _integer(word) < 0:
                    raise _LineError(word.column, word.text, "line number N must not be negative")
        return [w for w in words if w.letter != "N"]

    @staticmethod
    def _classify(words: list[_Word]) -> tuple[dict[str, _Word], _Word | None, dict[str, _Word]]:
        """G words by modal group, the M word, other words by letter; rejects unknown and repeated words."""
        g: dict[str, _Word] = {}
        m = None
        other: dict[str, _Word] = {}
        for word in words:
            if word.letter == "G":
                code = word.value
                if not code.is_integer() or int(code) not in _G_GROUPS:
                    raise _LineError(word.column, word.text, "unsupported G-code")
                group = _G_GROUPS[int(code)]
                if group in g:
                    raise _LineError(word.column, word.text, f"second G-code of the {group} group in one block")
                g[group] = word
            elif word.letter == "M":
                if m is not None:
                    raise _LineError(word.column, word.text, "only one M-code per block")
                if not word.value.is_integer() or int(word.value) not in _STOP_MCODES | PARAMETER_MCODES.keys():
                    raise _LineError(word.column, word.text, "unsupported M-code")
                m = word
            elif word.letter in _AXES + _ARC_WORDS + _OTHER_WORDS:
                if word.letter in other:
                    raise _LineError(word.column, word.text, f"word {word.letter} given twice in one block")
                other[word.letter] = word
            else:
                raise _LineError(word.column, word.text, f"unsupported word {word.letter}")
        return g, m, other

    def _target(self, axis_words: list[_Word], scale: float, absolute: bool) -> np.ndarray:
        q = self.q.copy()
        for word in axis_words:
            i = _AXES.index(word.letter)
            value = word.value * scale if i < 3 else math.radians(word.value) if i < 6 else word.value
            q[i] = value if absolute else q[i] + value
        return q

    @staticmethod
    def _dwell(word: _Word, p: _Word | None, lineno: int) -> Dwell:
        if p is None:
            raise _LineError(word.column, word.text, "G4 needs the dwell time P in seconds")
        if p.value < 0.0:
            raise _LineError(p.column, p.text, "dwell time P must not be negative")
        return Dwell(p.value, lineno)

    def _arc(self, q_end: np.ndarray, plane: int, clockwise: bool, other: dict[str, _Word], scale: float,
             lead: _Word) -> ArcSegment:
        """G2/G3 in the active plane, centre by offsets I J K (relative to the start) or by radius R."""
        (a, b, k), offset_letters, not_offset = _PLANES[plane]
        p0, p1 = self.q[:3], q_end[:3]
        if not_offset in other:
            word = other[not_offset]
            raise _LineError(word.column, word.text, f"{not_offset} is no centre offset in the G{plane} plane")
        chord = math.hypot(p1[a] - p0[a], p1[b] - p0[b])
        if "R" in other:
            for letter in offset_letters:
                if letter in other:
                    raise _LineError(other[letter].column, other[letter].text, "give either R or the centre offsets")
            centre = self._centre_from_radius(p0[[a, b]], p1[[a, b]], chord, clockwise, other["R"], scale)
        elif any(letter in other for letter in offset_letters):
            centre = np.array([p0[a], p0[b]]) + [other[c].value * scale if c in other else 0.0 for c in offset_letters]
        else:
            raise _LineError(lead.column, lead.text,
                             f"arc needs the centre offsets {' '.join(offset_letters)} or a radius R")
        r0 = math.hypot(p0[a] - centre[0], p0[b] - centre[1])
        r1 = math.hypot(p1[a] - centre[0], p1[b] - centre[1])
        if r0 <= ARC_RADIUS_TOLERANCE:
            raise _LineError(lead.column, lead.text, f"arc radius must exceed {ARC_RADIUS_TOLERANCE * 1e3:g} mm")
        if abs(r1 - r0) > ARC_RADIUS_TOLERANCE:
            raise _LineError(lead.column, lead.text,
                             f"end point is not on the arc: radius {r0 * 1e3:.6g} mm at start, "
                             f"{r1 * 1e3:.6g} mm at end")
        theta0 = math.atan2(p0[b] - centre[1], p0[a] - centre[0])
        theta1 = math.atan2(p1[b] - centre[1], p1[a] - centre[0])
        if chord <= MIN_TRAVEL:
            sweep = 2.0 * math.pi  # start = end: a full circle
        else:
            sweep = ((theta0 - theta1) if clockwise else (theta1 - theta0)) % (2.0 * math.pi)
            if sweep == 0.0:
                raise _LineError(lead.column, lead.text, "arc too short for its radius")
        sweep += 2.0 * math.pi * (self._turns(other.get("P")) - 1)
        unit = np.eye(3)
        centre3 = centre[0] * unit[a] + centre[1] * unit[b] + p0[k] * unit[k]
        return ArcSegment(self.q, q_end, centre3, unit[a], unit[b], unit[k], r0, r1, theta0,
                          -sweep if clockwise else sweep, p1[k] - p0[k])

    @staticmethod
    def _centre_from_radius(p0, p1, chord, clockwise, r_word: _Word, scale) -> np.ndarray:
        """Centre for R format: R > 0 takes the arc up to 180 degrees, R < 0 the longer one."""
        radius = abs(r_word.value) * scale
        if chord <= MIN_TRAVEL:
            raise _LineError(r_word.column, r_word.text, "R format needs an end point different from the start")
        half = 0.5 * chord
        if radius < half - ARC_RADIUS_TOLERANCE:
            raise _LineError(r_word.column, r_word.text, "radius R is smaller than half the distance to the end point")
        h = math.sqrt(max(radius**2 - half**2, 0.0))
        tangent = (p1 - p0) / chord
        left = np.array([-tangent[1], tangent[0]])
        side = -1.0 if clockwise else 1.0  # counter-clockwise short arcs have their centre on the left
        if r_word.value < 0.0:
            side = -side
        return 0.5 * (p0 + p1) + side * h * left

    @staticmethod
    def _turns(p: _Word | None) -> int:
        if p is None:
            return 1
        if not p.value.is_integer() or p.value < 1:
            raise _LineError(p.column, p.text, "number of turns P must be a positive integer")
        return int(p.value)

    @staticmethod
    def _mcode(m: _Word, p: _Word | None, lineno: int) -> list[Block]:
        code = _integer(m)
        if code in (0, 1):
            blocks: list[Block] = [ProgramStop(code == 1, lineno)]
        elif code in (2, 30):
            blocks = []
        else:
            node, parameter, value = PARAMETER_MCODES[code]
            if value is None:
                if p is None:
                    raise _LineError(m.column, m.text, f"M{code} needs the value P")
                low, high = PARAMETER_MCODE_RANGES.get(code, (-math.inf, math.inf))
                if not low <= p.value <= high:
                    raise _LineError(p.column, p.text, f"M{code} sets {node}.{parameter}: P must be in [{low:g}, {high:g}]")
                return [ParameterCommand(node, parameter, p.value, lineno)]
            blocks = [ParameterCommand(node, parameter, value, lineno)]
        if p is not None:
            raise _LineError(p.column, p.text, "P has no effect in this block")
        return blocks


def _feed_si(feed: float | None, scale: float, metric: int, motion: int) -> float | None:
    """Path-speed limit in the segment metric: length units/min -> m/s, deg/min -> rad/s."""
    if motion == 0 or feed is None or metric == 2:
        return None
    return feed * scale / 60.0 if metric == 0 else math.radians(feed) / 60.0


def program_text(source: object) -> str:
    """The program as text: a str as is, bytes decoded as UTF-8 (a leading byte order mark, as Windows
    editors save UTF-8, dropped); GCodeError with the line:col of the first byte that is not UTF-8
    (a Latin-1 or UTF-16 file) or when ``source`` is neither."""
    if isinstance(source, str):
        return source
    if isinstance(source, (bytes, bytearray)):
        source = bytes(source).removeprefix(b"\xef\xbb\xbf")
        try:
            return source.decode("utf-8")
        except UnicodeDecodeError as exc:
            before = bytes(source[:exc.start])
            line = before.count(b"\n") + 1
            column = len(before) - (before.rfind(b"\n") + 1) + 1
            bad = "byte " + " ".join(f"0x{b:02x}" for b in bytes(source[exc.start:exc.end]))
            raise GCodeError([Diagnostic(line, column, bad, "not UTF-8 text (a Latin-1, UTF-16 or binary file?)")]) from None
    raise GCodeError([Diagnostic(1, 1, type(source).__name__, "a program must be text")])


def parse_gcode(source: str | bytes, start_pose=None, start_force=None) -> Program:
    """Parse a program starting at start_pose (6, m and rad) and start_force (3, N), both zero by default.

    Raises GCodeError with every error (line:column, offending text, message); lines after M2/M30
    are not read. The start is needed because moves may give only some axes or be incremental."""
    text = program_text(source)
    start = np.zeros(9)
    if start_pose is not None:
        start[:6] = np.asarray(start_pose, dtype=float).reshape(6)
    if start_force is not None:
        start[6:] = np.asarray(start_force, dtype=float).reshape(3)
    if not np.all(np.isfinite(start)):
        raise ValueError("start_pose and start_force must be finite")
    parser = _Parser(start)
    diagnostics = []
    for lineno, line in enumerate(text.split("\n"), start=1):
        if parser.ended:
            break
        try:
            parser.line(lineno, line.removesuffix("\r"))
        except _LineError as err:
            diagnostics.append(Diagnostic(lineno, err.column, err.text, err.message))
    if diagnostics:
        raise GCodeError(diagnostics)
    return Program(tuple(parser.blocks), start, parser.q.copy())

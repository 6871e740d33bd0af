"""Program model of the cdpr G-code dialect (docs/gcode.md).

The parser (gcode.py) turns program text into a Program; the interpolator (interpolation.py)
turns a Program into set-points x_d, xdot_d, xddot_d and F_d,0 (thesis sections 2.3.2, 5.1.2).
Everything here is SI: m, rad, N, s. A path vector q is 9-D: q = [x y z a b c | u v w], i.e. the
pose x (Kardan angles, section 2.1.1) followed by the desired force F_d,0 of (5.2).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdpr_control.motion.path import FORCE, Segment


@dataclass(frozen=True)
class Diagnostic:
    """One error in a program: 1-based line and column, the offending text and what is wrong."""

    line: int
    column: int
    text: str
    message: str

    def __str__(self) -> str:
        return f"{self.line}:{self.column}: {self.message} ({self.text!r})"


class GCodeError(ValueError):
    """Raised by the parser with every error found in a program (at least one)."""

    def __init__(self, diagnostics):
        self.diagnostics = tuple(diagnostics)
        super().__init__("\n".join(str(d) for d in self.diagnostics))


@dataclass(frozen=True, eq=False)
class Motion:
    """G0/G1/G2/G3: one geometric segment.

    feed is the programmed limit of the path speed ds/dt in the segment's metric (m/s for
    position, rad/s for rotation-only moves); None for G0 rapids and force-only moves."""

    segment: Segment
    feed: float | None
    rapid: bool
    line: int


@dataclass(frozen=True)
class Dwell:
    """G4 P<seconds>: stand still for duration seconds."""

    duration: float
    line: int


@dataclass(frozen=True)
class ProgramStop:
    """M0 (optional=False) or M1 (optional=True): stop until resumed."""

    optional: bool
    line: int


@dataclass(frozen=True)
class ParameterCommand:
    """Set parameter `parameter` of ROS node `node` to `value` (M100..M104 or `#<node.param> = value`)."""

    node: str
    parameter: str
    value: bool | int | float | str
    line: int


Block = Motion | Dwell | ProgramStop | ParameterCommand


@dataclass(frozen=True, eq=False)
class Program:
    """A parsed program: blocks in execution order, the path vector q (9,) at start and end."""

    blocks: tuple[Block, ...]
    start: np.ndarray = field(repr=False)
    end: np.ndarray = field(repr=False)

    @property
    def end_pose(self) -> np.ndarray:
        """Programmed final pose x = [x y z a b c] (m, rad)."""
        return self.end[:6].copy()

    @property
    def end_force(self) -> np.ndarray:
        """Programmed final desired force F_d,0 (N)."""
        return self.end[FORCE].copy()

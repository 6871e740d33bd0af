"""A simulated hand: a user wrench profile (pushes, pulses, release) on the platform, section 5.2.

A profile is a list of segments, each started at its time through the simulator's one wrench pulse
(``Simulator.apply_pulse``, in a ROS graph the ``/sim/apply_wrench`` service), so a segment
replaces the one before it:

    Segment(0.5, (10, 0, 0, 0, 0, 0), "rectangle", 0.3)    # a 10 N pulse in x for 0.3 s
    Segment(2.0, (8, 0, 0, 0, 0, 0), "step")               # a constant push until the next segment
    Segment(4.0, release=True)                              # let go

The text form (command line, ``cdpr hand``) is one segment per ``;``:
``T SHAPE DURATION FX FY FZ [MX MY MZ]`` or ``T release``, e.g.
``"0.5 rectangle 0.3 10 0 0; 2 step 0 8 0 0; 4 release"``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cdpr_sim.wrench import SHAPES, WrenchPulse


@dataclass(frozen=True)
class Segment:
    t: float                                 # start, simulation time [s]
    wrench: tuple = (0.0,) * 6               # peak [N, N m], base frame
    shape: str = "step"                      # see cdpr_sim.wrench
    duration: float = 0.0                    # s (0 with step: until the next segment)
    release: bool = False                    # let go: no wrench from t on
    point: tuple = (0.0, 0.0, 0.0)           # application point in the platform frame [m]

    def __post_init__(self):
        if not (math.isfinite(self.t) and self.t >= 0.0):
            raise ValueError(f"segment time must be >= 0 s, got {self.t}")
        if not self.release:                 # validated by the pulse it becomes
            WrenchPulse(tuple(map(float, self.wrench)), tuple(map(float, self.point)), self.shape,
                        float(self.duration))

    def pulse(self) -> WrenchPulse | None:
        if self.release:
            return None
        return WrenchPulse(tuple(map(float, self.wrench)), tuple(map(float, self.point)), self.shape,
                           float(self.duration), 0.0, self.t)


class Hand:
    """A wrench profile applied to a simulator (in process) segment by segment."""

    def __init__(self, segments):
        self.segments = sorted(segments, key=lambda s: s.t)
        self.next = 0

    @classmethod
    def parse(cls, text: str) -> "Hand":
        segments = []
        for part in filter(None, (p.strip() for p in text.split(";"))):
            words = part.split()
            try:
                if len(words) == 2 and words[1] == "release":
                    segments.append(Segment(float(words[0]), release=True))
                    continue
                if len(words) not in (6, 9) or words[1] not in SHAPES:
                    raise ValueError
                values = [float(w) for w in words[3:]] + [0.0] * (9 - len(words))
                segments.append(Segment(float(words[0]), tuple(values), words[1], float(words[2])))
            except ValueError as exc:
                detail = f": {exc}" if str(exc) else ""
                raise ValueError(f"hand segment {part!r} is not 'T SHAPE DURATION FX FY FZ [MX MY MZ]' "
                                 f"or 'T release' (shapes: {', '.join(SHAPES)}){detail}") from None
        if not segments:
            raise ValueError("a hand profile needs at least one segment")
        return cls(segments)

    def due(self, t: float) -> list[Segment]:
        """Segments whose start time has come (each returned once)."""
        out = []
        while self.next < len(self.segments) and self.segments[self.next].t <= t + 1e-9:
            out.append(self.segments[self.next])
            self.next += 1
        return out

    def apply(self, sim) -> None:
        """Call before each ``sim.step``: starts the segments due at ``sim.t``."""
        for segment in self.due(sim.t):
            if segment.release:
                sim.clear_pulse()
            else:
                sim.apply_pulse(segment.wrench, segment.point, segment.shape, segment.duration)

    def wrench(self, t) -> np.ndarray:
        """The profile's wrench (N, 6) at times t (platform not rotated), for plots and checks."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.zeros((len(t), 6))
        for i, seg in enumerate(self.segments):
            end = self.segments[i + 1].t if i + 1 < len(self.segments) else np.inf
            pulse = seg.pulse()
            if pulse is None:
                continue
            mask = (t >= seg.t - 1e-9) & (t < end - 1e-9)
            out[mask] = np.outer([pulse.scale(tk) for tk in t[mask]], pulse.wrench)
        return out

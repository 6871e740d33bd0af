"""The simulated hand (thesis 5.2): profile text, segments started at their times on the
simulator, the profile's wrench over time, and the `cdpr hand` command line."""
import numpy as np
import pytest

from cdpr_sim.hand import Hand, Segment
from cdpr_tools.cli import build_parser
from cdpr_tools.hand_cmd import request


def test_parse_the_text_form():
    hand = Hand.parse("0.5 rectangle 0.3 10 0 0; 2 step 0 8 0 0 0 0 0.5; 4 release")
    a, b, c = hand.segments
    assert (a.t, a.shape, a.duration, a.wrench) == (0.5, "rectangle", 0.3, (10.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert b.wrench == (8.0, 0.0, 0.0, 0.0, 0.0, 0.5) and b.shape == "step"
    assert c.release and c.t == 4.0


@pytest.mark.parametrize("text", ["", "1 push 0.3 1 0 0", "1 rectangle 0 1 0 0", "x step 0 1 0 0", "1 step 0 1 0"])
def test_a_bad_profile_says_what_is_wrong(text):
    with pytest.raises(ValueError):
        Hand.parse(text)


class _Sim:
    """Records what the hand does to a simulator."""

    def __init__(self):
        self.t, self.calls = 0.0, []

    def apply_pulse(self, wrench, point, shape, duration):
        self.calls.append((self.t, shape, tuple(wrench)))

    def clear_pulse(self):
        self.calls.append((self.t, "clear", None))


def test_segments_start_once_at_their_time():
    hand = Hand([Segment(0.002, (1, 0, 0, 0, 0, 0), "rectangle", 0.001), Segment(0.004, release=True)])
    sim = _Sim()
    for k in range(10):
        sim.t = k * 1e-3
        hand.apply(sim)
    assert sim.calls == [(0.002, "rectangle", (1, 0, 0, 0, 0, 0)), (0.004, "clear", None)]


def test_profile_wrench_over_time():
    hand = Hand([Segment(1.0, (2, 0, 0, 0, 0, 0), "half_sine", 1.0), Segment(3.0, (0, 4, 0, 0, 0, 0), "step"),
                 Segment(4.0, release=True)])
    w = hand.wrench([0.5, 1.5, 2.5, 3.5, 4.5])
    np.testing.assert_allclose(w[:, 0], [0.0, 2.0, 0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(w[:, 1], [0.0, 0.0, 0.0, 4.0, 0.0], atol=1e-12)


def test_cli_builds_the_service_requests():
    args = build_parser().parse_args(["hand", "0.5 ramp 0.2 3 0 -1; 1 release", "--absolute"])
    assert args.absolute and args.service == "/sim/apply_wrench"
    push, release = Hand.parse(args.profile).segments
    r = request(push)
    assert (r.shape, r.duration, r.wrench.force.x, r.wrench.force.z) == ("ramp", 0.2, 3.0, -1.0)
    r = request(release)
    assert r.shape == "step" and r.duration == 0.0 and r.wrench.force.x == 0.0

"""Hand guiding (thesis 5.2) pushed, held and released in several directions with the shipped
parameter file on the default (mismatched) plant: the platform follows the push, stops after the
release, and every cable keeps the robot file's f_min."""
import numpy as np
import pytest

from cdpr_control.model.robot import load_robot
from cdpr_sim.hand import Segment
from cdpr_sim.hand_guiding import guiding_run

ENABLE, PUSH, RELEASE, END = 0.5, 0.6, 1.4, 2.0     # s


@pytest.mark.parametrize("name, force, direction", [
    ("ipanema3", 60.0, (1.0, 0.0, 0.0)),
    ("ipanema3", 60.0, (0.0, 0.0, 1.0)),
    ("ipanema3", 60.0, (-1.0, 1.0, 1.0)),
])
def test_push_hold_release_keeps_the_cables_tensed(name, force, direction):
    robot = load_robot(name)
    d = np.asarray(direction) / np.linalg.norm(direction)
    wrench = tuple(np.r_[force * d, 0.0, 0.0, 0.0])
    g = guiding_run([Segment(PUSH, wrench, "ramp", 0.2), Segment(PUSH + 0.2, wrench, "step"), Segment(RELEASE, release=True)],
                    END, robot_name=name, enable_at=ENABLE)
    r = g.run
    on = r.t > ENABLE
    moved = r.x_d[-1, :3] - r.x_d[0, :3]
    assert moved @ d > 2e-3                                            # followed the push
    assert np.linalg.norm(moved - (moved @ d) * d) < 0.2 * (moved @ d)   # along it
    speed = np.linalg.norm(np.diff(r.x_d[-100:, :3], axis=0), axis=1) / 1e-3
    assert speed.max() < 2e-3                                          # m/s: at rest after the release
    assert r.f[on].min() >= robot.cable.f_min.min()

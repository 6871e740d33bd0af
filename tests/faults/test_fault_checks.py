"""The checks the fault tests make on what they recorded (tests/cdpr_test_nodes/fault_graph.py) fail
where they must: a cable force out of its band for longer than 100 ms, a loop stopped for 1 s; the
excursions they find."""
from types import SimpleNamespace

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from cdpr_msgs.msg import CableForces
from std_msgs.msg import Header

from cdpr_control.model.robot import load_robot
from cdpr_test_nodes.fault_graph import PERIOD_NS, ROBOT, FaultGraph, Recording, excursions, longest_excursion


def recorded(forces: np.ndarray, command_stamps) -> SimpleNamespace:
    """What a FaultGraph would have recorded: one force vector per period, commands at the stamps."""
    msgs = [CableForces(header=Header(stamp=Time(sec=k * PERIOD_NS // 10**9, nanosec=k * PERIOD_NS % 10**9)), f=list(f))
            for k, f in enumerate(forces)]
    robot = load_robot(ROBOT)
    return SimpleNamespace(robot=robot, collector=SimpleNamespace(messages=lambda topic: msgs),
                           commands=lambda: [(t, np.zeros(robot.m)) for t in command_stamps])


def with_excursion(periods: int, value: float) -> SimpleNamespace:
    robot = load_robot(ROBOT)
    f = np.tile(robot.cable.f_min * 2.0, (1000, 1))
    f[400:400 + periods, 3] = value
    return recorded(f, range(0, 1000 * PERIOD_NS, PERIOD_NS))


def test_forces_in_the_band_or_briefly_out_pass():
    c = load_robot(ROBOT).cable
    FaultGraph.check_forces(with_excursion(0, 0.0))
    FaultGraph.check_forces(with_excursion(90, 0.4 * c.f_min[3]))        # 90 ms slack: allowed


@pytest.mark.parametrize("factor, limit", [(0.4, "f_min"), (1.6, "f_max")])
def test_a_force_out_of_the_band_for_longer_than_100_ms_fails(factor, limit):
    c = load_robot(ROBOT).cable
    with pytest.raises(AssertionError, match="out of"):
        FaultGraph.check_forces(with_excursion(150, factor * getattr(c, limit)[3]))


def test_a_loop_stopped_for_more_than_a_second_fails():
    robot = load_robot(ROBOT)
    f = np.tile(robot.cable.f_min * 2.0, (3000, 1))
    stamps = [*range(0, 500 * PERIOD_NS, PERIOD_NS), *range(1700 * PERIOD_NS, 3000 * PERIOD_NS, PERIOD_NS)]
    with pytest.raises(AssertionError, match="stopped"):
        FaultGraph.check_forces(recorded(f, stamps))


def test_excursions_are_the_stretches_longer_than_100_ms_one_running_at_the_end_included():
    robot = load_robot(ROBOT)
    c = robot.cable
    f = np.tile(c.f_min * 2.0, (1000, 1))
    f[100:150, 0] = 0.0                                      # 50 ms slack: not one
    f[300:420, 1] = 2.0 * c.f_max[1]                         # 120 ms beyond 1.5 f_max
    f[880:, 2] = 0.4 * c.f_min[2]                            # from 880 ms to the last period (999 ms)
    stamps = np.arange(1000) * PERIOD_NS
    assert excursions(stamps, f, c) == [(300 * PERIOD_NS, 419 * PERIOD_NS), (880 * PERIOD_NS, 999 * PERIOD_NS)]
    rec = Recording(robot, {"/ground_truth/cable_forces": recorded(f, []).collector.messages("")})
    assert rec.excursions(350 * PERIOD_NS, 500 * PERIOD_NS) == []          # 70 ms of it in the window
    assert rec.excursions(0, 950 * PERIOD_NS) == [(300 * PERIOD_NS, 419 * PERIOD_NS)]


def test_the_longest_excursion_of_any_length_is_measured_first_to_last_stamp():
    """The figure the push tests print: the longest out-of-band stretch, short ones included."""
    c = load_robot(ROBOT).cable
    f = np.tile(c.f_min * 2.0, (1000, 1))
    stamps = np.arange(1000) * PERIOD_NS
    assert longest_excursion(stamps, f, c) == 0
    f[100:150, 0] = 0.0                                      # 50 periods slack: 49 ms first to last
    f[300:320, 1] = 2.0 * c.f_max[1]
    assert longest_excursion(stamps, f, c) == 49 * PERIOD_NS
    f[990:, 2] = 0.4 * c.f_min[2]                            # running at the end: to the last stamp
    f[150:170, 3] = 0.0                                      # right after the first: one stretch of 70
    assert longest_excursion(stamps, f, c) == 69 * PERIOD_NS

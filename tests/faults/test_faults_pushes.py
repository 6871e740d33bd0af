"""Pushes beyond the cables' rating in the composed closed-loop graph (one process, lockstep,
IPAnema 3 Mini, default mismatched plant), issue 28's "Done when": 350 N during a program, and 900 N
then 500 N, at home and at a corner of ``cuboid_mini``. For each: the loop runs on (no gap of 1 s of
simulated time), commands finite within the rate limit, the force watch holds, a program through
the excursion does not end ``done``, the cables are back within [f_min, f_max] 1.0-1.5 s after the
push's end, and no simulated cable force leaves [0.5 f_min, 1.5 f_max] for more than 100 ms from
the push's end on (while a push beyond the cables lasts they must leave it). Times are the graph's
simulated ones. Each push case runs once, on a graph of its own (see :func:`pushed`), and the
tests assert on its recording.
"""
import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from cdpr_msgs.msg import ProgramStatus  # noqa: E402

from cdpr_test_nodes.fault_graph import (HANG_S, MS, FaultGraph, check_not_done, longest_excursion,  # noqa: E402
    program_ended)


AFTER_S = 1.5           # simulated time watched after a push's end
SETTLED_S = 1.0         # ... of which the last 0.5 s must have every force within [f_min, f_max]
CORNER = (-150.0, -100.0, -100.0)    # mm: cuboid_mini's first corner
# name -> (position [mm] pushed at, pushes: (force along x [N], duration [s], pause after it [s]),
# a program running through the pushes or None)
PUSHES = {
    "350_N_home_program": ((0.0, 0.0, 0.0), [(350.0, 0.5, 0.0)], "G21 G90\nG1 X20 F600\nG4 P10\nM30"),
    "900_N_then_500_N_home": ((0.0, 0.0, 0.0), [(900.0, 0.5, 0.5), (500.0, 0.5, 0.0)], None),
    "900_N_then_500_N_corner": (CORNER, [(900.0, 0.5, 0.5), (500.0, 0.5, 0.0)], None),
}


def pushed(position, pushes: list, program: str | None = None) -> dict:
    """On a graph of its own (a push beyond the cables' rating settles the plant's cables for good:
    after 900 N then 500 N at home, the hold released, a move to the corner tripped the watch again
    after each of five releases, so no later test could use the graph), move to ``position`` [mm], push the platform (``pushes`` in a row), optionally
    while ``program`` runs; watch until AFTER_S after the last push's end. -> {recording (what the
    graph recorded), start, began, end, until (stamps [ns]: before the program, the first push, the
    last push's end, the end of the watch), result (the program's, or None), watch (the fault that
    held, or None)}."""
    # state_timeout 30 s (wall): the interpreter plans a program beside the loop in this process; on
    # a loaded machine planning a 600 s dwell starved the loop for 5 s and failed the program by that
    # (seen in a stress run), which is not the fault tried here
    graph = FaultGraph("composed", lockstep_timeout=0.02, state_timeout=30.0)
    try:
        x, y, z = position
        moved = graph.start_program(f"G21 G90\nG1 X{x:g} Y{y:g} Z{z:g} F6000\nM30", "to_the_push")
        assert program_ended(moved).success
        graph.wait_running(periods=1000, timeout=HANG_S)      # 1 s standing: a clean stretch for the watch
        start = graph.newest_command()
        running = None
        if program is not None:
            running = graph.start_program(program, "pushed")
            graph.wait_program_state(ProgramStatus.RUNNING, timeout=HANG_S)
            graph.wait_running(periods=100, timeout=HANG_S)
        for k, (force, duration, pause) in enumerate(pushes):
            at = graph.push(force, duration)
            began = at if k == 0 else began
            end = at + int(duration * 1e9)
            graph.wait_stamp(end + int(pause * 1e9), timeout=HANG_S)
        until = end + int(AFTER_S * 1e9)
        graph.wait_stamp(until, timeout=HANG_S)
        result = None if running is None else program_ended(running)
        watch = graph.node("joint_command").watch.fault
        recording = graph.recording()
    finally:
        graph.close()
    stamps, f = recording.forces(end, until)
    late = f[stamps >= end + int(SETTLED_S * 1e9)]
    print(f"\npushes {pushes} at {position} mm (mismatched plant): after the end {f.min():.1f}..{f.max():.1f} N, "
          f"{SETTLED_S}-{AFTER_S} s after it {late.min():.2f}..{late.max():.2f} N; excursions (ms after the "
          f"end) {[((a - end) // MS, (b - end) // MS) for a, b in recording.excursions(end, until)]}, the longest "
          f"outside [0.5 f_min, 1.5 f_max] {longest_excursion(stamps, f, recording.robot.cable) // MS} ms; "
          f"held by {None if watch is None else watch.message}")
    return {"recording": recording, "start": start, "began": began, "end": end, "until": until, "result": result,
            "watch": watch}


class PushRuns:
    """Each case of PUSHES run once, when a test first asks for it (its cost in that test); a run
    that failed fails every test that asks for it, without running again."""

    def __init__(self):
        self.runs = {}

    def __getitem__(self, case: str) -> dict:
        if case not in self.runs:
            try:
                self.runs[case] = pushed(*PUSHES[case])
            except Exception as exc:        # noqa: BLE001 - raised again to each asking test
                self.runs[case] = exc
                raise
        if isinstance(self.runs[case], Exception):
            raise AssertionError(f"the run of {case} failed: {self.runs[case]!r}")
        return self.runs[case]


@pytest.fixture(scope="module")
def push_runs() -> PushRuns:
    return PushRuns()


def test_a_program_pushed_beyond_the_cables_fails_and_does_not_end_done(push_runs):
    """Issue 28: a program through a cable-force excursion (a 350 N push, more than the eight 40 N
    cables hold) must not end ``done``: it fails naming the force watch."""
    run = push_runs["350_N_home_program"]
    assert run["recording"].excursions(run["began"], run["until"]), "the push left every force in its band"
    check_not_done(run["recording"], run["result"], "pushed", run["start"])
    assert run["watch"] is not None


@pytest.mark.parametrize("case", list(PUSHES))
def test_after_a_push_the_loop_runs_and_the_cables_are_back_within_their_limits(push_runs, case):
    """Issue 28: after a 350 N push forces stayed at 1.5-7.9 N (below f_min 5 N) 20 s later, after
    900 N then 500 N four cables at 0-0.07 N for 10 s. Now the loop runs on through the pushes (no
    gap of 1 s), every command is finite and within the rate limit, the watch held, and 1.0-1.5 s
    after the last push's end every cable is within [f_min, f_max]."""
    run = push_runs[case]
    recording = run["recording"]
    assert run["watch"] is not None
    recording.check_commands(since_stamp=run["start"])
    stamps, f = recording.forces(run["began"], run["until"])
    assert len(stamps) > 1 and np.diff(stamps).max() <= 1_000 * MS
    late = f[stamps >= run["end"] + int(SETTLED_S * 1e9)]
    c = recording.robot.cable
    assert len(late) and np.all(late >= c.f_min) and np.all(late <= c.f_max), (late.min(), late.max())


@pytest.mark.parametrize("case", list(PUSHES))
def test_after_a_push_no_cable_force_leaves_the_band_for_more_than_100_ms(push_runs, case):
    """Issue 28, "Done when": no simulated cable force out of [0.5 f_min, 1.5 f_max] for more than
    100 ms from the push's end on (while a push beyond the cables lasts, they must leave it)."""
    run = push_runs[case]
    run["recording"].check_forces(since_stamp=run["end"], until_stamp=run["until"])

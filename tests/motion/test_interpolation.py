"""Jerk-limited interpolator: chain rule, limits, exact geometry, pause/resume/cancel, commands."""
import math

import numpy as np
import pytest

from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.path import Chain, LineSegment
from cdpr_control.motion.interpolation import (AxisLimits, Interpolator, Limits, ProgramState, path_limits,
    sample_program)

DT = 1e-3
LIMITS = Limits()


def run(interp, max_steps=100_000, until=None):
    points = []
    for _ in range(max_steps):
        points.append(interp.step())
        if until is not None and until(points[-1]):
            break
        if points[-1].state in (ProgramState.DONE, ProgramState.CANCELLED, ProgramState.FAILED):
            break
    return points


def stopping_distance(v0, A, J):
    """Shortest jerk-limited stop from cruise speed v0 (acceleration 0): jerk -J up to -ap,
    hold, jerk +J back to 0 (closed form, independent of ruckig)."""
    ap = min(A, math.sqrt(J * v0))
    t1 = t3 = ap / J
    t2 = max((v0 - ap**2 / J) / ap, 0.0)
    x, v, a = 0.0, v0, 0.0
    for T, j in ((t1, -J), (t2, 0.0), (t3, J)):
        x += v * T + a * T**2 / 2 + j * T**3 / 6
        v += a * T + j * T**2 / 2
        a += j * T
    assert abs(v) < 1e-9 and abs(a) < 1e-9
    return x


def test_limits_are_validated():
    with pytest.raises(ValueError):
        AxisLimits(1.0, -1.0, 1.0)
    with pytest.raises(ValueError):
        AxisLimits(math.inf, 1.0, 1.0)
    with pytest.raises(ValueError):
        Interpolator(parse_gcode("G0 X1"), LIMITS, dt=0.0)


def test_path_limits_of_a_line_are_the_group_limits_or_the_feed():
    chain = Chain([LineSegment(np.zeros(9), np.r_[0.3, 0.4, 0, np.zeros(6)], 0)])
    assert path_limits(chain, LIMITS, None) == (0.5, 2.0, 20.0)
    assert path_limits(chain, LIMITS, 0.1)[0] == 0.1
    rotating = Chain([LineSegment(np.zeros(9), np.r_[0.1, 0, 0, 1.0, 0, 0, 0, 0, 0], 0)])
    # |da/ds| = 10 rad/m: rotation limits (1 rad/s, 5 rad/s^2, 50 rad/s^3) / 10 bind
    np.testing.assert_allclose(path_limits(rotating, LIMITS, None), (0.1, 0.5, 5.0))


def test_path_limits_of_an_arc_keep_centripetal_terms_within_limits():
    program = parse_gcode("G1 X20 F60000\nG3 X20 Y0 I-20")  # r = 20 mm circle
    chain = Chain([program.blocks[1].segment])
    v, a, j = path_limits(chain, LIMITS, None)
    r = 0.02
    assert v**2 / r <= 0.5 * LIMITS.translation.acceleration * (1 + 1e-12)
    assert v**2 / r + a <= LIMITS.translation.acceleration * (1 + 1e-12)
    assert v**3 / r**2 + 3 * v * a / r + j <= LIMITS.translation.jerk * (1 + 1e-12)


def test_set_points_obey_the_chain_rule():
    """xd and xdd are the time derivatives of x: compare with central differences on an arc
    with rotation and force changing along it."""
    s = sample_program(parse_gcode("G1 X50 F6000\nG3 X0 Y50 I-50 A20 W-10 F12000"), LIMITS, DT)
    v_fd = (s.x[2:] - s.x[:-2]) / (2 * DT)
    a_fd = (s.xd[2:] - s.xd[:-2]) / (2 * DT)
    # central differences are exact up to (DT^2/6) * jerk-like terms
    assert np.max(np.abs(v_fd - s.xd[1:-1])) < 1e-5
    assert np.max(np.abs(a_fd - s.xdd[1:-1])) < 0.02


def test_line_reaches_the_end_exactly_within_limits():
    program = parse_gcode("G1 X123.4 Y-56.7 Z8.9 A5 F60000")
    s = sample_program(program, LIMITS, DT)
    np.testing.assert_array_equal(s.x[-1], program.end_pose)
    assert s.state[-1] is ProgramState.DONE
    assert np.all(s.xd[-1] == 0) and np.all(s.xdd[-1] == 0)
    p = s.x[:, :3]
    assert np.max(np.linalg.norm(s.xd[:, :3], axis=1)) <= 0.5 * (1 + 1e-12)
    assert np.max(np.linalg.norm(s.xdd[:, :3], axis=1)) <= 2.0 * (1 + 1e-9)
    assert np.max(np.linalg.norm(np.diff(s.xdd[:, :3], axis=0), axis=1)) / DT <= 20.0 * (1 + 1e-6)
    # stays on the straight line
    direction = program.end_pose[:3] / np.linalg.norm(program.end_pose[:3])
    assert np.max(np.linalg.norm(p - np.outer(p @ direction, direction), axis=1)) < 1e-15


def test_forces_are_interpolated_with_the_motion():
    s = sample_program(parse_gcode("G1 X100 U10 V-20 W30 F6000"), LIMITS, DT)
    fraction = s.x[:, 0] / 0.1
    np.testing.assert_allclose(s.force, np.outer(fraction, [10, -20, 30]), atol=1e-12)


def test_force_only_move_uses_the_force_limits():
    s = sample_program(parse_gcode("G1 W-50 F100"), LIMITS, DT)
    rate = np.abs(np.diff(s.force[:, 2])) / DT
    assert rate.max() <= LIMITS.force.velocity * (1 + 1e-9)
    assert rate.max() > 0.9 * LIMITS.force.velocity
    assert np.all(s.x == 0)
    assert s.force[-1, 2] == -50.0


def test_smooth_joints_are_passed_at_speed_and_corners_stop():
    straight = sample_program(parse_gcode("G1 X100 F6000\nX200"), LIMITS, DT)
    corner = sample_program(parse_gcode("G1 X100 F6000\nY100"), LIMITS, DT)
    at_joint = np.argmin(np.abs(straight.x[:, 0] - 0.1))
    assert np.linalg.norm(straight.xd[at_joint]) == pytest.approx(0.1, rel=1e-3)
    k = np.flatnonzero((corner.x[:, 0] == 0.1) & (corner.x[:, 1] == 0.0))
    assert len(k) >= 1 and np.all(corner.xd[k] == 0)
    # two half circles of the same circle are one smooth path too
    halves = sample_program(parse_gcode("G1 X10 F600\nG3 X-10 Y0 I-10\nG3 X10 Y0 I10"), LIMITS, DT)
    on_circle = halves.line >= 2
    assert np.min(np.linalg.norm(halves.xd[on_circle][50:-50, :3], axis=1)) > 0.009


def test_arc_points_stay_on_the_programmed_circle():
    program = parse_gcode("G1 X30 Y10 F60000\nG2 X-10 Y10 I-20 J0 P2\nG18 G3 X-30 Z0 I-10 K0")
    s = sample_program(program, LIMITS, DT)
    first = s.line == 2
    assert np.max(np.abs(np.hypot(s.x[first, 0] - 0.01, s.x[first, 1] - 0.01) - 0.02)) < 1e-12
    second = s.line == 3
    assert np.max(np.abs(np.hypot(s.x[second, 0] + 0.02, s.x[second, 2]) - 0.01)) < 1e-12
    assert np.all(s.x[second, 1] == 0.01)


def test_dwell_and_program_stop():
    program = parse_gcode("G1 X10 F6000\nG4 P0.25\nM0\nG1 X20")
    interp = Interpolator(program, LIMITS, DT)
    points = run(interp, until=lambda p: p.state is ProgramState.PAUSED)
    dwell = [p for p in points if p.line == 2]
    assert len(dwell) == 250 and all(np.all(p.x == dwell[0].x) for p in dwell)
    for _ in range(100):  # M0 holds until resumed
        held = interp.step()
        assert held.state is ProgramState.PAUSED and held.x[0] == 0.01
    assert interp.resume()
    rest = run(interp)
    assert rest[-1].state is ProgramState.DONE and rest[-1].x[0] == 0.02
    assert rest[-1].progress == 1.0


def test_optional_stop_only_when_enabled():
    program = parse_gcode("M1\nG1 X10 F6000")
    assert run(Interpolator(program, LIMITS, DT))[-1].state is ProgramState.DONE
    assert Interpolator(program, LIMITS, DT, optional_stop=True).step().state is ProgramState.PAUSED


def test_commands_are_reported_and_can_be_awaited():
    program = parse_gcode("G1 X10 F6000\nM100 P0.5\nG1 X20")
    points = run(Interpolator(program, LIMITS, DT))
    issued = [c for p in points for c in p.commands]
    assert [(c.node, c.parameter, c.value, c.line) for c in issued] == [("force_distribution", "tension_level", 0.5, 2)]
    interp = Interpolator(program, LIMITS, DT, wait_for_commands=True)
    points = run(interp, until=lambda p: p.state is ProgramState.WAITING)
    assert points[-1].commands and points[-1].x[0] == 0.01
    assert interp.step().state is ProgramState.WAITING
    interp.command_done(True)
    assert run(interp)[-1].state is ProgramState.DONE
    failing = Interpolator(program, LIMITS, DT, wait_for_commands=True)
    run(failing, until=lambda p: p.state is ProgramState.WAITING)
    failing.command_done(False, "node not found")
    assert failing.step().state is ProgramState.FAILED
    assert failing.error.startswith("line 2:") and "node not found" in failing.error


def test_progress_is_monotonic_from_zero_to_one():
    program = parse_gcode("G1 X100 F6000\nG4 P0.1\nG2 X0 Y0 I-50")
    interp = Interpolator(program, LIMITS, DT)
    progress = [p.progress for p in run(interp)]
    assert progress[0] < 0.01 and progress[-1] == 1.0
    assert np.all(np.diff(progress) >= 0)
    assert interp.duration == pytest.approx(len(progress) * DT, abs=2 * DT)


def cruise_then(command, program_text="G1 X4000 F60000", at=0.9):
    """Run a long line until cruising at v_max, then call command(interp); return points before/after."""
    interp = Interpolator(parse_gcode(program_text), LIMITS, DT)
    before = run(interp, until=lambda p: p.t >= at)
    assert command(interp)
    after = run(interp, until=lambda p: p.state in (ProgramState.PAUSED, ProgramState.CANCELLED))
    return interp, before, after


def test_cancel_stops_within_the_jerk_limited_stopping_distance_without_velocity_jump():
    interp, before, after = cruise_then(Interpolator.cancel)
    last = before[-1]
    v0 = np.linalg.norm(last.xd[:3])
    assert v0 == pytest.approx(0.5) and np.linalg.norm(last.xdd) < 1e-9
    assert after[0].state is ProgramState.CANCELLING and after[-1].state is ProgramState.CANCELLED
    travelled = after[-1].x[0] - last.x[0]
    bound = stopping_distance(v0, LIMITS.translation.acceleration, LIMITS.translation.jerk)
    assert bound - v0 * DT <= travelled <= bound + v0 * DT
    xd = np.array([p.xd for p in before[-2:] + after])
    xdd = np.array([p.xdd for p in before[-2:] + after])
    assert np.max(np.abs(np.diff(xd[:, 0]))) <= LIMITS.translation.acceleration * DT * (1 + 1e-9)
    assert np.max(np.abs(np.diff(xdd[:, 0]))) <= LIMITS.translation.jerk * DT * (1 + 1e-6)
    assert np.all(after[-1].xd == 0) and np.all(after[-1].x[1:] == 0)
    assert interp.step().state is ProgramState.CANCELLED and not interp.resume()


def test_pause_and_resume_keep_the_path_and_reach_the_end():
    interp, before, after = cruise_then(Interpolator.pause, "G1 X4000 Y1000 F60000")
    assert after[-1].state is ProgramState.PAUSED and np.all(after[-1].xd == 0)
    held = interp.step()
    np.testing.assert_array_equal(held.x, after[-1].x)
    assert interp.resume()
    rest = run(interp)
    points = before + after + [held] + rest
    x = np.array([p.x for p in points])
    xd = np.array([p.xd for p in points])
    assert np.max(np.abs(x[:, 0] / 4 - x[:, 1])) < 1e-15  # on the line y = x / 4
    assert np.max(np.linalg.norm(np.diff(xd[:, :3], axis=0), axis=1)) <= 2.0 * DT * (1 + 1e-9)
    assert rest[-1].state is ProgramState.DONE and rest[-1].x[0] == 4.0 and rest[-1].x[1] == 1.0


def test_resume_while_still_braking_accelerates_again_smoothly():
    interp = Interpolator(parse_gcode("G1 X400 F60000"), LIMITS, DT)
    before = run(interp, until=lambda p: p.t >= 0.9)
    interp.pause()
    braking = run(interp, until=lambda p: p.t >= 1.0)
    assert braking[-1].state is ProgramState.PAUSING and interp.resume()
    rest = run(interp)
    xd = np.array([p.xd[0] for p in before + braking + rest])
    assert np.max(np.abs(np.diff(xd))) <= 2.0 * DT * (1 + 1e-9)
    assert rest[-1].x[0] == 0.4


def test_pause_near_the_end_stops_exactly_at_the_end_point():
    program = parse_gcode("G1 X100 F60000\nG1 Y100")
    interp = Interpolator(program, LIMITS, DT)
    first = run(interp, until=lambda p: p.x[0] > 0.0999)  # braking distance exceeds the rest
    assert first[-1].xd[0] > 0 and interp.pause()
    after = run(interp, until=lambda p: p.state is ProgramState.PAUSED)
    assert after[-1].x[0] == 0.1 and after[-1].x[1] == 0.0
    assert interp.resume() and run(interp)[-1].x[1] == 0.1


def test_cancel_on_an_arc_stays_on_the_arc():
    interp, before, after = cruise_then(Interpolator.cancel, "G1 X100 F60000\nG2 X100 Y0 I-100 P3", at=3.0)
    x = np.array([p.x for p in before + after])
    on_arc = np.array([p.line for p in before + after]) == 2
    assert np.max(np.abs(np.linalg.norm(x[on_arc, :2], axis=1) - 0.1)) < 1e-12
    assert after[-1].state is ProgramState.CANCELLED


def test_cancel_while_paused_waiting_or_dwelling_is_immediate():
    interp = Interpolator(parse_gcode("G4 P1"), LIMITS, DT)
    interp.step()
    assert interp.cancel() and interp.state is ProgramState.CANCELLED
    assert not interp.cancel()


def test_a_move_longer_than_the_planner_handles_is_a_gcode_error_with_its_line():
    from cdpr_control.motion.program import GCodeError
    from cdpr_control.motion.interpolation import MAX_MOVE_DURATION

    # 300 mm at 1 mm/min: 18,000 s (ruckig's time law ends near 7,600 s, code -101 unknown to its bindings)
    with pytest.raises(GCodeError, match="^2:1: this move takes 18000 s") as err:
        Interpolator(parse_gcode("G90 G1 X0 F600\nG1 X300 F1"))
    assert err.value.diagnostics[0].line == 2
    # just below the refusal the move is planned, and lasts what its feed says
    feed = 300 / (0.99 * MAX_MOVE_DURATION) * 60                # mm/min
    interp = Interpolator(parse_gcode(f"G90 G1 X300 F{feed:.6f}"))
    assert interp.duration == pytest.approx(0.99 * MAX_MOVE_DURATION, rel=1e-3)

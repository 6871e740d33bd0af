"""What each single-entry memo of the per-period code saves ("recompute when these inputs change"):
per scheme the cost of a miss (the computation, plus the key) and of a hit (the key and its
comparison), wall time by time.perf_counter_ns over many calls, median of repeats (a loaded
machine inflates both). The library's memos are timed through their own methods with the memo
cleared (miss) or not (hit); the nodes' as the same calls their memo wraps, on one set-point message.

    .venv/bin/python scripts/memo_costs.py [--calls 20000] [--repeats 9]

A hit saves miss - hit per period while the inputs repeat (holding, a pause, a dwell); while they
change every period (a moving set-point) the memo costs its hit. docs/performance.md ("Memos")
quotes the figures; the schemes that save under ~2 us a period were dropped. The five nodes' set-point
memos (marked dropped) went in session 24: the interpreter's payload carries x_d, ẋ_d, ẍ_d converted
once (conversions.setpoint_from_msg), which leaves them nothing to keep.
"""
from __future__ import annotations

import argparse
import statistics
import struct
import time

import numpy as np


def per_call_ns(fn, calls: int, repeats: int) -> float:
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        for _ in range(calls):
            fn()
        runs.append((time.perf_counter_ns() - t0) / calls)
    return statistics.median(runs)


def schemes():
    """name -> (miss, hit): two callables, the computation with its key, and the key alone."""
    from cdpr_msgs.msg import ControllerState, OperationalSetpoint

    from cdpr_control import kernels
    from cdpr_control.control.force_setpoint import ForceSetpoint, ForceSetpointParams
    from cdpr_control.control.hybrid_force_control import parse_state
    from cdpr_control.control.safety import ForceWatch, SafetyConfig, SafetyMonitor, all_finite
    from cdpr_control.model.robot import load_robot
    from cdpr_control.ros.conversions import (accel_from_msg, accel_to_msg, pose_from_msg, pose_to_msg,
        twist_from_msg, twist_to_msg)
    from cdpr_control.nodes.gcode_interpreter import _setpoint_body

    robot = load_robot("ipanema3_mini")
    x = robot.home + np.array([0.01, -0.02, 0.03, 0.01, 0.0, -0.01])
    sp = OperationalSetpoint(pose=pose_to_msg(x), velocity=twist_to_msg(np.full(6, 0.01)),
                             acceleration=accel_to_msg(np.full(6, 0.1)))
    pose = sp.pose
    values = struct.Struct("7d").pack

    def pose_key(pose):    # the dropped nodes' key: the pose's seven values as bytes
        p, o = pose._position, pose._orientation
        return values(p._x, p._y, p._z, o._x, o._y, o._z, o._w)
    key = pose_key(pose)
    out = {}

    def pose_hit():
        k = pose_key(pose)
        return k is None or k != key
    out["nodes/ospc _setpoint (x_d, list, finite; dropped)"] = (
        lambda: (pose_key(pose), (lambda x_d: (x_d, x_d.tolist(), all_finite(x_d.tolist())))(pose_from_msg(pose))),
        pose_hit)
    out["nodes/forward_kinematics _setpoint_pose (x_d, finite; dropped)"] = (
        lambda: (pose_key(pose), (lambda x_d: all_finite(x_d))(pose_from_msg(pose))), pose_hit)
    out["nodes/joint_command _setpoint_pose (x_d; dropped)"] = (lambda: (pose_key(pose), pose_from_msg(pose)), pose_hit)
    out["nodes/friction_compensation _wrap_angles (beta of the IK; dropped)"] = (
        lambda: (pose_key(pose), kernels.inverse_kinematics_fields(robot, pose_from_msg(pose), "beta")), pose_hit)
    pack = struct.Struct("19d").pack

    def sp_key():
        p, o = pose._position, pose._orientation
        v, om, a, al = sp.velocity._linear, sp.velocity._angular, sp.acceleration._linear, sp.acceleration._angular
        return pack(p._x, p._y, p._z, o._x, o._y, o._z, o._w, v._x, v._y, v._z, om._x, om._y, om._z,
                    a._x, a._y, a._z, al._x, al._y, al._z)
    k19 = sp_key()
    out["nodes/force_distribution _setpoint (x_d, xdot_d, xddot_d; dropped)"] = (
        lambda: (sp_key(), pose_from_msg(pose), twist_from_msg(sp.velocity), accel_from_msg(sp.acceleration)),
        lambda: sp_key() != k19)
    state = ControllerState(controller="hybrid_force_controller:D")
    last = state.controller
    out["nodes/force_distribution _contact (parse_state; dropped)"] = (
        lambda: (state.controller != last, parse_state(state.controller)), lambda: state.controller != last)
    q, xd, xdd = np.concatenate([x, np.zeros(3)]), np.full(6, 0.01), np.full(6, 0.1)
    gkey = (q.tobytes(), xd.tobytes(), xdd.tobytes(), 3)

    def gcode_miss():
        return (q.tobytes(), xd.tobytes(), xdd.tobytes(), 3), _setpoint_body(q, xd, xdd, 3)
    out["nodes/gcode_interpreter _setpoint_fields (messages, x_d, xdot_d, xddot_d)"] = (
        gcode_miss, lambda: (q.tobytes(), xd.tobytes(), xdd.tobytes(), 3) != gkey)
    fs = ForceSetpoint(robot, 1e-3, ForceSetpointParams())
    xdot_d, xddot_d = np.full(6, 0.01), np.full(6, 0.1)

    def w_dyn_key():       # what the dropped `_model` memo keyed w_dyn on (session 22)
        return (np.asarray(x, dtype=float).tobytes(), np.asarray(xdot_d, dtype=float).tobytes(),
                np.asarray(xddot_d, dtype=float).tobytes(), kernels.ENABLED)
    key = w_dyn_key()
    out["control/force_setpoint w_dyn (the `_model` memo without A^T; dropped)"] = (
        lambda: (w_dyn_key(), kernels.platform_wrench(robot, x, xdot_d, xddot_d)), lambda: w_dyn_key() != key)
    cog = np.array([0.0, 0.0, -0.05])

    def payload_miss():
        fs._payload_memo.clear()
        return fs.payload_wrench(x, xdot_d, xddot_d, 1.0, cog)
    fs.payload_wrench(x, xdot_d, xddot_d, 1.0, cog)
    out["control/force_setpoint payload_wrench (payload kinematics)"] = (
        payload_miss, lambda: fs.payload_wrench(x, xdot_d, xddot_d, 1.0, cog))
    mon = SafetyMonitor(SafetyConfig())
    f = np.full(robot.m, 50.0).tolist()
    f_min, f_max = robot.cable.f_min, robot.cable.f_max

    def inside_miss():
        mon._limits.clear()
        return mon._inside(f, f_min, f_max, 5.0)
    out["control/safety SafetyMonitor._inside (max f_min, min f_max)"] = (
        inside_miss, lambda: mon._inside(f, f_min, f_max, 5.0))
    watch = ForceWatch(SafetyConfig(), 1e-3)

    def bounds_miss():
        watch._bounds.clear()
        return watch._limits(f_min, f_max, robot.m)
    out["control/safety ForceWatch._limits (bands)"] = (bounds_miss, lambda: watch._limits(f_min, f_max, robot.m))

    def packed_miss():
        kernels._packed_memo.clear()
        return kernels._packed(robot, x)
    kernels._packed(robot, x)
    out["kernels _packed (the IK of x_d, shared by the stages)"] = (packed_miss, lambda: kernels._packed(robot, x))
    from cdpr_control.kernels import friction as kf
    from cdpr_control.model.friction import PulleySeries
    fr = robot.friction
    series = PulleySeries(fr.mu, fr.F_pv, fr.n_pulleys, fr.beta_inner)
    beta, = kernels.inverse_kinematics_fields(robot, x, "beta")
    beta = beta.copy()

    def tables_miss():
        kf._tables_memo.clear()
        return kf._series_tables(series, beta)
    kf._series_tables(series, beta)
    out["kernels/friction _series_tables (alpha, gamma)"] = (tables_miss, lambda: kf._series_tables(series, beta))

    def series_miss():
        series._beta_key = series._beta_seen = None
        return series.tables(beta)
    series.tables(beta)
    out["model/friction PulleySeries.tables (numpy reference)"] = (series_miss, lambda: series.tables(beta))
    from cdpr_control.model.memo import Memo

    def fields_views_miss():  # kernels.inverse_kinematics_fields: the four views the FK takes, made again
        kernels._packed(robot, x)[1].clear()
        return kernels.inverse_kinematics_fields(robot, x, "q", "AT", "cT", "beta")
    out["kernels inverse_kinematics_fields views (q, A^T, c^T, beta; kernels._packed hit)"] = (
        fields_views_miss, lambda: kernels.inverse_kinematics_fields(robot, x, "q", "AT", "cT", "beta"))
    memo, inline_key = Memo(), [key, None]
    memo(key, pose_from_msg, pose)

    def inline_hit():
        k = pose_key(pose)
        if k is None or k != inline_key[0]:
            inline_key[:] = k, pose_from_msg(pose)
        return inline_key[1]
    out["the Memo helper's own cost: a hit through Memo vs inline"] = (
        lambda: memo(pose_key(pose), pose_from_msg, pose), inline_hit)
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=9)
    args = parser.parse_args(argv)
    print(f"{'scheme':62s} {'miss us':>8s} {'hit us':>8s} {'saves us':>9s}")
    for name, (miss, hit) in schemes().items():
        miss(), hit()                                        # compiled, warm
        m, h = (per_call_ns(fn, args.calls, args.repeats) / 1e3 for fn in (miss, hit))
        print(f"{name:62s} {m:8.2f} {h:8.2f} {m - h:9.2f}")


if __name__ == "__main__":
    main()

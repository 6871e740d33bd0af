"""One Fig. 3.4: the in-process ControlLoop and the composed node graph compute the same winch
commands, period by period, bit for bit.

The graph (graphs/closed_loop.yaml, composed, lockstep) runs the shipped floor_contact_ipanema3
program on the IPAnema 3 against a simulated floor (nominal plant, as test_hybrid_force_graph.py),
with hybrid force control in contact (approach, brake, force control, release) and load
compensation on (its ``enabled``: the identification, its offset x_d,LC and the payload wrench in
the force distribution all act). The bag holds every period's inputs of the controller (the
set-point with its force F_d,0 and the winch state θ, θ̇, F_s) and its outputs. ControlLoop, built
from the same parameter file (:func:`control_loop_params` with the hybrid force controller's and
the load compensation's sections), replays those inputs period by period, so neither timing nor
the program's start enter: every stage's output of every period must equal the graph's topic of
that period exactly. The admittance controller's state is an input too (its user wrench w_Adm, the
force set-point's hand's reserve while guided: tests/graph/test_hand_reserve_graph.py replays a
guided run with these functions). The graph has no blends of its own (the loop's CFC/OSPC/HPFC blends): they
stay at weight 1.0, where they multiply exactly.

The replay also compares the intermediate topics (cable forces, pose, wrench, force distribution,
CFC, OSPC, hybrid force controller and load compensation states) so that a drift names the stage
and the first period where it begins.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from cdpr_control import programs  # noqa: E402
from cdpr_control.control.hybrid_force_control import HPFCParams, parse_state  # noqa: E402
from cdpr_control.control.load_compensation import LoadCompensationParams, LoadCompensationStage  # noqa: E402
from cdpr_control.control.loop import ControlLoop  # noqa: E402
from cdpr_control.control.params import control_loop_params, load_params_file  # noqa: E402
from cdpr_control.model.robot import load_robot  # noqa: E402
from cdpr_control.ros.conversions import accel_from_msg, from_vector3, pose_from_msg, twist_from_msg  # noqa: E402
from cdpr_test_nodes.graph import wait_for  # noqa: E402
from cdpr_tools.bag import BagReader  # noqa: E402
from cdpr_tools.demo_cmd import GRAPH, surface_parameters  # noqa: E402
from cdpr_tools.launch import Launcher, RecordSpec  # noqa: E402
from cdpr_tools.launch_file import load_launch_file  # noqa: E402
from cdpr_tools.program_client import run_program  # noqa: E402

# the case: robot, program name and text, a floor to press on, load compensation on
FLOOR = SimpleNamespace(robot="ipanema3", name="floor_contact_ipanema3", program=programs.read("floor_contact_ipanema3"),
                        floor=True, load_compensation=True)
INPUTS = ["/setpoint", "/winch/state", "/admittance_controller/state"]
OUTPUTS = ["/winch/command", "/cable_forces", "/platform/pose", "/platform/wrench", "/force_distribution",
           "/cable_force_controller/state", "/ospc/state", "/hybrid_force_controller/state",
           "/load_compensation/state", "/load_compensation/payload"]


def _stamp(msg) -> int:
    s = msg.header.stamp
    return s.sec * 1_000_000_000 + s.nanosec


def record_graph(case, bag) -> SimpleNamespace:
    """Run the case's program through the composed lockstep graph (nominal plant), recording INPUTS
    and OUTPUTS to ``bag``; the launcher is torn down on leaving, also on a failure."""
    robot = load_robot(case.robot)
    description = load_launch_file(GRAPH, {"robot": case.robot})
    description.record = RecordSpec(output=str(bag), topics=INPUTS + OUTPUTS)
    for spec in description.nodes:
        if spec.module.endswith("winch_platform_sim"):
            spec.parameters.append({"plant": "nominal"})
            if case.floor:
                spec.parameters.append(surface_parameters(robot, "floor", 1e6))
        elif spec.module.endswith("load_compensation") and case.load_compensation:
            # a file with the node's own section: an inline mapping is a "/**" one, which the
            # parameter file's load_compensation section (enabled: false) would override
            lc_on = Path(bag).parent / "load_compensation_on.yaml"
            lc_on.write_text(yaml.safe_dump({"load_compensation": {"ros__parameters": {"enabled": True}}}))
            spec.parameters.append(str(lc_on))
    with Launcher(description, mode="composed") as launch:
        sim = next(n for n in launch.nodes if n.get_name() == "winch_platform_sim").sim
        result = run_program(case.program, case.name, timeout=600.0, server_timeout=120.0)   # a loaded machine
        t_end = sim.t
        wait_for(lambda: sim.t >= t_end + 0.05, timeout=60.0, what="the loop to run on after the program")
        errors = list(launch.errors)
    return SimpleNamespace(result=result, errors=errors)


def read_periods(bag) -> tuple[list[int], dict[str, dict[int, object]]]:
    """(the stamps of the periods the graph commanded, topic -> stamp -> message)."""
    series: dict[str, dict[int, object]] = {}
    for m in BagReader(bag).messages(INPUTS + OUTPUTS):
        series.setdefault(m.topic, {})[_stamp(m.msg)] = m.msg
    stamps = sorted(set(series["/winch/command"]) & set(series["/winch/state"]) & set(series["/setpoint"]))
    # the replay starts where the graph started: its filters, calibration windows and integrators
    # have no other history (the launcher holds a composed graph until the recorder subscribed)
    first = {topic: min(values) for topic, values in series.items()}
    assert stamps and stamps[0] == 0 and set(first.values()) == {0}, f"the bag misses the first periods: {first}"
    return stamps, series


def loop_from_params(robot, dt: float, load_compensation: bool) -> ControlLoop:
    """ControlLoop of the robot's parameter file, with the hybrid force controller of its
    ``hybrid_force_controller`` section and the load compensation of its ``load_compensation``
    section (``enabled`` as the graph's) as the offset stage named like the node."""
    file = load_params_file(robot.file.stem)
    hpfc = file["hybrid_force_controller"]
    loop_params = replace(control_loop_params(robot),
                          hpfc=HPFCParams(**{k: v for k, v in hpfc.items() if k in HPFCParams.__dataclass_fields__
                                             and k != "T_MA"},
                                          T_MA=file["cable_force_controller"]["T_MA"]),
                          hpfc_enabled=False)
    lc = LoadCompensationParams(**{**{k: v for k, v in file["load_compensation"].items()
                                      if k in LoadCompensationParams.__dataclass_fields__},
                                   "enabled": load_compensation})
    stage = LoadCompensationStage(robot, dt, lc,
                                  feed_force_setpoint=file["force_distribution"]["payload_input"])
    return ControlLoop(robot, dt, loop_params, {"load_compensation": stage})


def _hpfc_enabled(series, stamps) -> list[bool]:
    """The hybrid force controller's ``enabled`` per period (M103 ... M104 of the program), from its
    state messages: idle (I) it reports ``enabled`` as it is; A-D are entered and kept only while
    enabled (else it releases, R), so there it is on; in R it may be either, and stays as it was."""
    out, enabled = [], False
    for t in stamps:
        msg = series["/hybrid_force_controller/state"][t]
        state = parse_state(msg.controller)
        if state == "I":
            enabled = bool(msg.enabled)
        elif state != "R":
            enabled = True
        out.append(enabled)
    return out


def user_wrench(series, stamps, k: int):
    """The loop's ``w_user`` of period k: the admittance controller's w_Adm of t_k-1 while it guided
    (the force distribution node's ``guiding_controller`` input), else None."""
    state = series["/admittance_controller/state"].get(stamps[k - 1]) if k else None
    return np.asarray(state.feedback, dtype=float) if state is not None and state.enabled else None


def replay(stamps, series, robot, load_compensation: bool) -> list[dict]:
    """ControlLoop.step on every recorded period's inputs -> per period, the differences
    (max |loop - graph|) of each compared quantity."""
    dt = 1e-3
    loop = loop_from_params(robot, dt, load_compensation)
    enabled = _hpfc_enabled(series, stamps)
    rows = []
    for k, t_ns in enumerate(stamps):
        sp, ws = series["/setpoint"][t_ns], series["/winch/state"][t_ns]
        loop.set_parameter("hybrid_force_controller", "enabled", enabled[k])
        s = loop.step(t_ns * 1e-9, pose_from_msg(sp.pose), twist_from_msg(sp.velocity),
                      accel_from_msg(sp.acceleration), np.asarray(ws.position), np.asarray(ws.velocity),
                      np.asarray(ws.effort), from_vector3(sp.force), user_wrench(series, stamps, k))
        g = {topic: series[topic].get(t_ns) for topic in OUTPUTS}
        fd, cfc, ospc = g["/force_distribution"], g["/cable_force_controller/state"], g["/ospc/state"]
        hpfc, lc = g["/hybrid_force_controller/state"], g["/load_compensation/state"]
        rows.append({
            "cable_forces": _diff(s.f, g["/cable_forces"].f),
            "platform/pose": _diff(s.x[:3], _position(g["/platform/pose"].pose)),
            "platform/wrench": _diff(s.w, _wrench(g["/platform/wrench"].wrench)),
            "load_compensation": _diff(s.offsets["load_compensation"], lc.output),
            "force_distribution": _diff(s.f_d, fd.f_d),
            "hybrid_force_controller": _diff(s.x_hpfc, hpfc.output) + (s.hpfc.state != parse_state(hpfc.controller)),
            "cable_force_controller": _diff(s.dq_cfc, cfc.output),
            "ospc": _diff(s.x_ospc, ospc.output),
            "winch/command": _diff(s.theta_d, g["/winch/command"].position),
        })
    return rows


def _diff(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))))


def _position(pose):
    return [pose.position.x, pose.position.y, pose.position.z]


def _wrench(w):
    return [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]


# Where the two may differ, and by how much (everything else: bit for bit). The OSPC node gets the
# pose estimate as geometry_msgs/Pose, whose orientation is a quaternion: Kardan angles -> quaternion
# -> Kardan angles changes them by ~1e-17 rad, which its PI integrates (up to ~1e-17 m, rad); summed
# with the other offsets that rounds differently in some periods (~4e-15 m on θ_d). The loop hands
# its stages the estimate itself.
TOLERANCE = {"ospc": 1e-12, "winch/command": 1e-12}


def first_differences(rows) -> dict[str, tuple[int, float]]:
    """stage -> (first period where the loop and the graph differ beyond TOLERANCE, the difference)."""
    out = {}
    for name in rows[0]:
        bound = TOLERANCE.get(name, 0.0)
        k = next((k for k, r in enumerate(rows) if not r[name] <= bound), None)
        if k is not None:
            out[name] = (k, rows[k][name])
    return out


def run_case(case, tmp_path_factory) -> SimpleNamespace:
    bag = tmp_path_factory.mktemp("loop_equals_graph") / "bag"
    run = record_graph(case, bag)
    stamps, series = read_periods(bag)
    return SimpleNamespace(**vars(run), stamps=stamps, series=series)


def assert_loop_equals_graph(case, run) -> list[dict]:
    assert run.result.success, run.result.message
    assert not run.errors
    rows = replay(run.stamps, run.series, load_robot(case.robot), case.load_compensation)
    print(f"\n{case.name}: {len(rows)} periods; largest difference loop - graph per stage over the run: "
          + ", ".join(f"{name} {max(r[name] for r in rows):.1e}" for name in rows[0]))
    assert first_differences(rows) == {}
    return rows


@pytest.fixture(scope="module")
def floor_run(tmp_path_factory):
    return run_case(FLOOR, tmp_path_factory)


def test_floor_program_with_load_compensation_gives_the_same_winch_commands_in_loop_and_graph(floor_run):
    series, stamps = floor_run.series, floor_run.stamps
    states = [parse_state(series["/hybrid_force_controller/state"][t].controller) for t in stamps]
    # the case covers contact and load compensation: every state of the contact, an offset x_d,LC
    assert {"A", "B", "D", "R"} <= set(states)
    assert max(abs(series["/load_compensation/state"][t].output[2]) for t in stamps) > 0.0
    assert_loop_equals_graph(FLOOR, floor_run)


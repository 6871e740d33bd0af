"""Hand guiding through the shipped node graph (graphs/closed_loop.yaml, IPAnema 3 Mini, composed,
lockstep): switched on by the service, pushed by the simulated hand through /sim/apply_wrench, a
program refused meanwhile, switched off; one set-point per period and no jump at either switch; a
program afterwards starts where the hand left the platform (one launch serves these). Free-running,
the interpreter's forwarding and the admittance node's catch-up are tested node by node (a
free-running graph on a loaded test machine tests the machine)."""
import time
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from cdpr_msgs.msg import ControllerState, OperationalSetpoint
from std_srvs.srv import SetBool

from cdpr_control.ros.conversions import pose_from_msg
from cdpr_sim.hand import Hand
from cdpr_test_nodes.graph import Collector, Spinner, wait_for
from cdpr_tools.demo_cmd import GRAPH
from cdpr_tools.hand_cmd import apply_profile
from cdpr_tools.launch import Launcher
from cdpr_tools.launch_file import load_launch_file
from cdpr_tools.program_client import run_program
from cdpr_tools.ros_graph import graph_node, spin_future, spin_until

PERIOD_NS = 1_000_000


def _switch(on: bool):
    with graph_node("switch") as node:
        client = node.create_client(SetBool, "/admittance_controller/hand_guiding")
        assert spin_until(node, client.service_is_ready, 30.0)
        return spin_future(node, client.call_async(SetBool.Request(data=on)), 30.0, "hand_guiding")


@pytest.fixture(scope="module")
def guided():
    spinner = Spinner()
    collector = spinner.add(Collector, topics={"/setpoint": OperationalSetpoint,
                                               "/admittance_controller/state": ControllerState})
    try:
        description = load_launch_file(GRAPH, {"robot": "ipanema3_mini"})
        with Launcher(description, mode="composed") as launch:
            sim = next(n for n in launch.nodes if n.get_name() == "winch_platform_sim").sim
            wait_for(lambda: collector.count("/setpoint") > 50, timeout=60.0, what="the loop to run")
            on = _switch(True)
            apply_profile(Hand.parse("0.05 rectangle 0.25 14 0 0"), log=lambda _: None)
            # from when the push went out (after the hand node's discovery, which takes a varying
            # share of simulated time, the more the faster the loop runs): 0.25 s push, 0.3 s on
            t_push = sim.t
            wait_for(lambda: sim.t >= t_push + 0.55, timeout=120.0, what="the push")
            with pytest.raises(RuntimeError, match="rejected"):
                run_program("G21 G90\nG1 X0 F600\nM30", "while guided", timeout=60.0)
            x_guided = sim.output.x.copy()
            x_sp_guided = pose_from_msg(collector.messages("/setpoint")[-1].pose)
            off = _switch(False)
            t_off = sim.t
            wait_for(lambda: sim.t >= t_off + 0.3, timeout=120.0, what="the hand-over")
            x_held = pose_from_msg(collector.messages("/setpoint")[-1].pose)
            result = run_program("G21 G91\nG1 X-5 F1200\nM30", "after guiding", timeout=120.0)
            t_end = sim.t
            wait_for(lambda: sim.t >= t_end + 0.05, timeout=30.0, what="the end of the program")
            errors = list(launch.errors)
        yield SimpleNamespace(on=on, off=off, x_guided=x_guided, x_sp_guided=x_sp_guided,
                              x_held=x_held, result=result, errors=errors,
                              setpoints=collector.messages("/setpoint"),
                              states=collector.messages("/admittance_controller/state"))
    finally:
        spinner.close()


def test_switch_service_and_push_move_the_set_point(guided):
    assert guided.on.success and guided.off.success and not guided.errors
    assert any(s.enabled for s in guided.states)
    assert guided.x_sp_guided[0] > 0.01              # the push left zone 1 (R_1 = 0.01 m)
    assert guided.x_held[0] == pytest.approx(guided.x_sp_guided[0], abs=2e-3)   # braked to rest, held
    assert guided.x_guided[0] == pytest.approx(guided.x_sp_guided[0], abs=1e-3)  # the platform followed


def test_one_set_point_per_period_and_no_jump(guided):
    stamps = np.array([s.header.stamp.sec * 10**9 + s.header.stamp.nanosec for s in guided.setpoints])
    assert np.all(np.diff(stamps) == PERIOD_NS)
    x = np.array([pose_from_msg(s.pose) for s in guided.setpoints])
    v_max = 0.25                                      # the admittance's default, below the program's 0.5 m/s
    # the state of t_k says whether the set-point of t_k+1 came from the admittance controller
    enabled_at = {s.header.stamp.sec * 10**9 + s.header.stamp.nanosec: s.enabled for s in guided.states}
    guided_steps = np.array([enabled_at.get(t, False) for t in stamps[:-1]])
    assert guided_steps.sum() > 500 and not guided.states[-1].enabled
    assert np.abs(np.diff(x[:, 0]))[guided_steps].max() <= v_max * 1e-3 + 1e-9
    assert np.abs(np.diff(x[:, 0])).max() <= 0.5 * 1e-3 + 1e-9      # the program's limit after


def test_program_after_guiding_starts_where_the_hand_left(guided):
    assert guided.result.success, guided.result.message
    x_end = pose_from_msg(guided.setpoints[-1].pose)
    assert x_end[0] == pytest.approx(guided.x_held[0] - 0.005, abs=1e-6)


def test_parameters_are_validated_live_and_a_refusal_keeps_the_old_value():
    from rclpy.parameter import Parameter

    from cdpr_control.nodes.admittance_controller import AdmittanceControllerNode
    from cdpr_control.ros.qos import STATUS
    from cdpr_msgs.msg import ProgramStatus

    spinner = Spinner()
    try:
        node = spinner.add(AdmittanceControllerNode)
        box = node.get_parameter("zones.free.box").value
        result = node.set_parameters([Parameter("zones.rest.radius", value=0.05)])[0]   # outside the 0.03 m box
        assert not result.successful and "rest sphere" in result.reason
        assert node.get_parameter("zones.rest.radius").value == 0.01
        # a box whose wall would leave the wrench-feasible workspace is shrunk to fit, and said so
        result = node.set_parameters([Parameter("zones.free.box", value=[0.3, 0.3, 0.3, 0.05, 0.05, 0.05])])[0]
        assert result.successful and "clipped" in node.clipping_note
        assert np.all(node.controller.zones.box < [0.3, 0.3, 0.3, 0.05, 0.05, 0.05])
        assert node.set_parameters([Parameter("zones.free.box", value=list(box))])[0].successful
        assert node.clipping_note == "" and list(node.controller.zones.box) == list(box)
        assert node.set_parameters([Parameter("zones.free.d", value=[100.0] * 6)])[0].successful
        assert node.controller.zones.zones[1].d[0] == 100.0                 # applied without a restart
        status = node.create_publisher(ProgramStatus, "program_status", STATUS)
        status.publish(ProgramStatus(state=ProgramStatus.RUNNING))
        wait_for(lambda: node.program_state == ProgramStatus.RUNNING, what="the program status")
        result = node.set_parameters([Parameter("hand_guiding", value=True)])[0]
        assert not result.successful and "program is running" in result.reason
        assert not node.controller.enabled
    finally:
        spinner.close()


def _probe_setpoint(node, stamp_ns, x, enabled, pubs):
    from cdpr_control.ros.base import CdprNode
    from cdpr_control.ros.conversions import pose_to_msg

    header = CdprNode.header(stamp_ns)
    pubs["setpoint"].publish(OperationalSetpoint(header=header, pose=pose_to_msg(x)))
    pubs["state"].publish(ControllerState(header=header, controller="probe_src", enabled=enabled))


def test_free_running_interpreter_forwards_ends_on_silence_and_refuses_a_jump():
    """sync_mode latest: the newest source set-point is forwarded; a silent source ends hand guiding
    (the last pose held); a source that starts away from the held pose is refused."""
    from rclpy.parameter import Parameter

    from cdpr_control.nodes.gcode_interpreter import GCodeInterpreterNode
    from cdpr_control.ros.qos import CONTROL

    spinner = Spinner()
    try:
        ns = "/free_running_probe"
        interp = spinner.add(GCodeInterpreterNode, namespace=ns, parameter_overrides=[
            Parameter("sync_mode", value="latest"), Parameter("setpoint_source", value="probe_src"),
            Parameter("source_timeout", value=0.1)])
        probe = spinner.add(Collector, topics={f"{ns}/setpoint": OperationalSetpoint})
        pubs = {k: probe.create_publisher(t, f"{ns}/probe_src/{k}", CONTROL)
                for k, t in (("setpoint", OperationalSetpoint), ("state", ControllerState))}
        wait_for(lambda: all(p.get_subscription_count() for p in pubs.values()), what="the interpreter")
        home = interp.robot.home
        count = lambda: probe.count(f"{ns}/setpoint")                            # noqa: E731
        last_x = lambda: pose_from_msg(probe.messages(f"{ns}/setpoint")[-1].pose)  # noqa: E731

        def publish_until(x, condition, what):
            def step():
                _probe_setpoint(probe, interp.get_clock().now().nanoseconds, x, True, pubs)
                return count() > 0 and condition()
            wait_for(step, what=what)

        near = home + np.array([5e-4, 0, 0, 0, 0, 0])
        publish_until(near, lambda: abs(last_x()[0] - near[0]) < 1e-12, "forwarding")
        assert interp.guided is not None
        wait_for(lambda: interp.guided is None, what="the end of hand guiding after the source fell silent")
        np.testing.assert_allclose(last_x(), near, atol=1e-12)          # held where the source left it
        far = home + np.array([0.02, 0, 0, 0, 0, 0])
        start = count()
        publish_until(far, lambda: count() > start + 50, "set-points while a far source is enabled")
        assert interp.guided is None
        np.testing.assert_allclose(last_x(), near, atol=1e-12)          # refused: no jump
    finally:
        spinner.close()


def test_free_running_admittance_node_integrates_the_skipped_periods():
    """sync_mode latest: measurements 10 periods apart advance the virtual system by 10 periods
    (the wrench held), as the library does, so the guided motion keeps real time."""
    from geometry_msgs.msg import WrenchStamped
    from rclpy.parameter import Parameter

    from cdpr_control.control.admittance import AdmittanceController, settings_from
    from cdpr_control.model.dynamics import gravity_wrench
    from cdpr_control.nodes.admittance_controller import AdmittanceControllerNode
    from cdpr_control.ros.base import CdprNode
    from cdpr_control.ros.conversions import pose_to_msg, wrench_to_msg
    from cdpr_control.ros.qos import CONTROL

    spinner = Spinner()
    try:
        ns = "/free_running_adm"
        node = spinner.add(AdmittanceControllerNode, namespace=ns, parameter_overrides=[
            Parameter("sync_mode", value="latest"), Parameter("hand_guiding", value=True)])
        probe = spinner.add(Collector, topics={f"{ns}/admittance_controller/state": ControllerState})
        pub_sp = probe.create_publisher(OperationalSetpoint, f"{ns}/setpoint", CONTROL)
        pub_w = probe.create_publisher(WrenchStamped, f"{ns}/platform/wrench", CONTROL)
        wait_for(lambda: pub_sp.get_subscription_count() and pub_w.get_subscription_count(), what="the node")
        robot = node.robot
        params, zones, _ = settings_from({}, robot)
        reference = AdmittanceController(robot, node.dt, params, zones)
        reference.enable()
        w = gravity_wrench(robot, robot.home)
        x = robot.home.copy()
        for k in range(6):
            stamp = k * 10 * 1_000_000                                # every 10th period arrives
            header = CdprNode.header(stamp)
            pub_sp.publish(OperationalSetpoint(header=header, pose=pose_to_msg(x)))
            time.sleep(0.05)
            w_k = w + (np.r_[5.0, 0, 0, 0, 0, 0] if k else 0.0)     # tare at k = 0, then a 5 N push
            pub_w.publish(WrenchStamped(header=header, wrench=wrench_to_msg(w_k)))
            wait_for(lambda: probe.count(f"{ns}/admittance_controller/state") > k, what="the state")
            out = reference.step(w_k, x, periods=1 if k == 0 else 10)
            x = out.x
        got = probe.messages(f"{ns}/admittance_controller/state")[-1].output
        np.testing.assert_allclose(got, x, atol=1e-9)
        assert x[0] > 1e-4                                              # it moved
    finally:
        spinner.close()


def _guided_from_start(periods: int, tmp_path, lockstep_timeout: float) -> tuple[dict, int]:
    """The shipped graph in lockstep with hand guiding on from the start and no dead band (the
    residual wrench of noise and friction drives it): stamp -> (set-point pose, admittance output),
    and the simulator's count of missed deadlines."""
    description = load_launch_file(GRAPH, {"robot": "ipanema3_mini"})
    override = tmp_path / "guided.yaml"          # by node name: a "/**" entry would not beat the file's
    override.write_text(yaml.safe_dump({
        "admittance_controller": {"ros__parameters": {"hand_guiding": True, "dead_band": [0.0] * 6,
                                                      "tare_on_enable": False}},
        "winch_platform_sim": {"ros__parameters": {"lockstep_timeout": lockstep_timeout}}}))
    for spec in description.nodes:
        if spec.module.endswith(("admittance_controller", "winch_platform_sim")):
            spec.parameters.append(str(override))
    spinner = Spinner()
    collector = spinner.add(Collector, topics={"/setpoint": OperationalSetpoint,
                                               "/admittance_controller/state": ControllerState})
    try:
        with Launcher(description, mode="composed") as launch:
            sim = next(n for n in launch.nodes if n.get_name() == "winch_platform_sim").sim
            wait_for(lambda: sim.steps >= periods + 5, timeout=300.0, what=f"{periods} periods")
            missed = next(n for n in launch.nodes if n.get_name() == "winch_platform_sim").missed_deadlines
        stamp = lambda m: m.header.stamp.sec * 10**9 + m.header.stamp.nanosec       # noqa: E731
        sp = {stamp(m): tuple(pose_from_msg(m.pose)) for m in collector.messages("/setpoint")}
        st = {stamp(m): tuple(m.output) for m in collector.messages("/admittance_controller/state")}
        return {t: (sp[t], st[t]) for t in sp if t in st and t <= periods * PERIOD_NS}, missed
    finally:
        spinner.close()


def test_lockstep_hand_guiding_is_deterministic(tmp_path):
    """Same seed, same graph: the guided set-points and admittance outputs of two runs are equal
    bit for bit (the collector may join a few periods late; the common periods are compared), also
    when the simulator's lockstep_timeout is shorter than the graph takes for one period (3 ms
    against about 5-10): a composed graph that is slow, not stopped, misses no deadline, so a
    loaded machine cannot change the run (before, the simulator advanced on its watchdog while
    the command was still queued in the process: 103 missed deadlines, 995 of 1001 periods differed)."""
    (a, missed_a), (b, missed_b) = _guided_from_start(1000, tmp_path, 1.0), _guided_from_start(1000, tmp_path, 0.003)
    assert missed_a == missed_b == 0
    common = sorted(set(a) & set(b))
    assert len(common) > 800
    assert all(a[t] == b[t] for t in common)
    moved = max(abs(a[t][1][0]) for t in common)
    assert moved > 0.0                                  # the residual wrench did move the virtual system

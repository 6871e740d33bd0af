"""Stability preconditions (issue 17, item 3): force control without OSPC needs a positive
definite geometric stiffness K_g (section 3.1.3); the loop refuses a configuration without it."""
import numpy as np
import pytest

from cdpr_control.control.loop import ControlLoop, ControlLoopParams
from cdpr_control.control.force_setpoint import ForceSetpointParams
from cdpr_control.model.robot import load_robot
from cdpr_control.control.preconditions import check_force_control, geometric_stiffness_margin
from cdpr_control.model.stiffness import geometric_stiffness
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_sim.startup import startup_forces


def test_mini_at_home_has_an_indefinite_K_g_at_every_tension_level():
    robot = load_robot("ipanema3_mini")
    for level in (0.0, 0.5, 1.0):
        f = startup_forces(robot, robot.home, level)
        lam = geometric_stiffness_margin(robot, robot.home, f)
        K_g = geometric_stiffness(inverse_kinematics(robot, robot.home), f)
        assert lam == pytest.approx(np.linalg.eigvalsh(0.5 * (K_g + K_g.T)).min())
        assert lam < -1.0
        assert "section 3.1.3" in check_force_control(robot, robot.home, f, ospc_enabled=False)
        assert check_force_control(robot, robot.home, f, ospc_enabled=True) is None


def test_loop_refuses_force_control_without_ospc_where_K_g_is_indefinite():
    robot = load_robot("ipanema3_mini")
    with pytest.raises(ValueError, match="positive definite geometric stiffness"):
        ControlLoop(robot, 1e-3, ControlLoopParams(ospc_enabled=False))
    ControlLoop(robot, 1e-3, ControlLoopParams(ospc_enabled=True))                 # with OSPC: fine
    ControlLoop(robot, 1e-3, ControlLoopParams(mode="ik_only", ospc_enabled=False))  # no force control


def test_a_live_switch_off_of_the_ospc_is_refused_with_the_reason():
    robot = load_robot("ipanema3_mini")
    loop = ControlLoop(robot, 1e-3, ControlLoopParams())
    theta = inverse_kinematics(robot, robot.home).q
    F_s = np.full(robot.m, 10.0)
    loop.step(0.0, robot.home, np.zeros(6), np.zeros(6), theta, np.zeros(robot.m), F_s)
    loop.params.ospc_enabled = False
    for k in range(1, 20):
        loop.step(k * 1e-3, robot.home, np.zeros(6), np.zeros(6), theta, np.zeros(robot.m), F_s)
    assert "section 3.1.3" in loop.refusal and loop.blend_ospc.value == 1.0
    loop.params.mode = "ik_only"                  # no force control: nothing to refuse
    loop.step(0.02, robot.home, np.zeros(6), np.zeros(6), theta, np.zeros(robot.m), F_s)
    assert loop.refusal is None


def test_ipanema3_needs_tension_for_force_control_without_ospc():
    """IPAnema 3 at home: K_g is indefinite at minimal tension, positive definite at medium tension."""
    robot = load_robot("ipanema3")
    with pytest.raises(ValueError):
        ControlLoop(robot, 1e-3, ControlLoopParams(ospc_enabled=False))
    medium = ControlLoopParams(ospc_enabled=False, force=ForceSetpointParams(tension_level=0.5))
    ControlLoop(robot, 1e-3, medium)


def test_ospc_node_states_the_precondition_when_disabled():
    """The node cannot see the joint command's mode: disabling the OSPC where K_g is indefinite
    is warned about on /diagnostics with the reason (the node publishes self.precondition)."""
    from required import import_or_skip

    rclpy = import_or_skip("rclpy")
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from cdpr_control.nodes.ospc import OSPCNode

    context = Context()
    rclpy.init(context=context)
    try:
        node = OSPCNode(context=context, parameter_overrides=[Parameter("robot", value="ipanema3_mini")])
        assert node.precondition is None
        assert node.set_parameters([Parameter("enabled", value=False)])[0].successful
        assert "positive definite geometric stiffness" in node.precondition
        node.set_parameters([Parameter("enabled", value=True)])
        assert node.precondition is None
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)

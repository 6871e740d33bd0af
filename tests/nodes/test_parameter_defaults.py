"""One source of truth per parameter default (issue 17, item 6): the nodes declare the stage
dataclasses' defaults, and the single-process loop reads the same per-robot parameter files as the
node graph."""
import numpy as np
import pytest

from required import import_or_skip

from cdpr_control.control.cable_force_control import CFCParams
from cdpr_control.control.params import STAGES, control_loop_params, default, load_params_file
from cdpr_control.control.ospc import OSPCParams
from cdpr_control.control.safety import SafetyConfig

import_or_skip("rclpy")
from cdpr_control.nodes import cable_force_controller, forward_kinematics, joint_command, ospc  # noqa: E402
from cdpr_control.control.pose_estimator import PoseEstimator  # noqa: E402


@pytest.mark.parametrize("node, module", [("cable_force_controller", cable_force_controller), ("ospc", ospc),
                                          ("joint_command", joint_command)])
def test_node_defaults_are_the_dataclass_defaults(node, module):
    cls = STAGES[node][1]
    names = {f for f in cls.__dataclass_fields__}
    checked = 0
    for spec in module.PARAMS:
        if spec.name in names:
            assert spec.default == default(node, spec.name), spec.name
            checked += 1
    assert checked >= 3


def test_the_drifted_defaults_have_one_value_each():
    """widen_band and x_sat had one value in the node, another in the dataclass."""
    assert dict((s.name, s.default) for s in cable_force_controller.PARAMS)["widen_band"] == CFCParams().widen_band
    assert dict((s.name, s.default) for s in ospc.PARAMS)["x_sat"] == OSPCParams().x_sat.tolist()
    assert dict((s.name, s.default) for s in joint_command.PARAMS)["max_position_lag"] == SafetyConfig().max_position_lag


@pytest.mark.parametrize("robot", ["ipanema3", "ipanema3_mini"])
def test_control_loop_reads_the_robot_parameter_file(robot):
    file = load_params_file(robot)
    p = control_loop_params(robot)
    assert p.cfc.widen_band == file["cable_force_controller"]["widen_band"]
    assert p.cfc.F_sat_n == file["cable_force_controller"]["F_sat_n"]
    np.testing.assert_array_equal(p.ospc.x_sat, file["ospc"]["x_sat"])
    np.testing.assert_array_equal(p.force.f_min, file["force_distribution"]["f_min"])
    assert p.safety.force_tolerance == file["joint_command"]["force_tolerance"]
    assert p.calibration_window == file["/**"]["calibration_window"]     # FK and CFC nodes: the same value
    assert p.mode == file["joint_command"]["mode"] if "mode" in file["joint_command"] else p.mode == "force_control"
    assert control_loop_params(robot, mode="ik_only").mode == "ik_only"


def test_forward_kinematics_node_defaults_are_the_estimator_defaults():
    import inspect

    defaults = {k: v.default for k, v in inspect.signature(PoseEstimator).parameters.items()}
    for spec in forward_kinematics.PARAMS:
        assert spec.default == defaults[spec.name], spec.name

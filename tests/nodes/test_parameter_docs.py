"""One declaration per parameter (issue 24, item 4): a node module's ``parameters(robot)`` is the
whole declaration of the node's parameters; the node declares exactly that list with its ranges and
descriptions, the stage dataclasses hold the defaults and are built from the parameters of their
field names, and docs/parameters.md is generated from the same lists."""
import importlib.util
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from required import import_or_skip

from cdpr_control.control.params import DEFAULTS, SECTIONS, section, stage_field
from cdpr_control.model.robot import load_robot

rclpy = import_or_skip("rclpy")
from rclpy.parameter import Parameter  # noqa: E402

from cdpr_control.ros.base import COMMON_PARAMS  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
MINI = load_robot("ipanema3_mini")


def parameter_table():
    spec = importlib.util.spec_from_file_location("parameter_table", ROOT / "scripts" / "parameter_table.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


TABLE = parameter_table()
MODULES = TABLE.node_modules()


def test_docs_parameters_md_is_current():
    assert (ROOT / "docs" / "parameters.md").read_text() == TABLE.render(), \
        "docs/parameters.md is stale: run `make parameter-table`"


def test_every_node_module_has_a_section():
    text = (ROOT / "docs" / "parameters.md").read_text()
    assert {"cable_force_controller", "force_distribution", "joint_command", "winch_platform_sim"} <= set(MODULES)
    for node in MODULES:
        assert f"## `{node}`" in text, node


@pytest.mark.parametrize("node", sorted(SECTIONS))
def test_stage_parameters_default_to_the_dataclass_and_build_it(node):
    """Every parameter named like a field of its stage's dataclass has that field's default and
    section() of the declared defaults is the dataclass default (force limits and friction come
    from the robot file: those are compared with the robot's)."""
    specs = MODULES[node].parameters(MINI)
    cls = SECTIONS[node][1]
    names = {f.name for f in fields(cls)}
    declared = {s.name: s.default for s in specs if s.name in names}
    assert len(declared) >= 3
    built = section(cls, declared)
    for name, value in declared.items():
        assert stage_field(node, name) == f"{SECTIONS[node][0]}.{name}"
        expected = getattr(DEFAULTS[node], name)
        if expected is None or name in ("f_min", "f_max"):     # the robot file's values
            expected = {"f_min": MINI.cable.f_min, "f_max": MINI.cable.f_max}.get(name, getattr(MINI.friction, name, None))
        np.testing.assert_array_equal(getattr(built, name), expected, err_msg=name)


def test_switches_name_their_loop_field():
    assert stage_field("cable_force_controller", "enabled") == "cfc_enabled"
    assert stage_field("forward_kinematics", "calibration_window") == "calibration_window"
    assert stage_field("ospc", "allow_unstable") == ""


def test_units_are_read_from_the_description():
    specs = {s.name: s for s in MODULES["friction_compensation"].parameters(MINI)}
    assert specs["F_pv"].unit == "N s/m" and specs["enabled"].unit == ""
    assert specs["mu"].type_name == "double_array" and specs["enabled"].type_name == "bool"
    sim = {s.name: s for s in MODULES["winch_platform_sim"].parameters(MINI)}
    assert sim["initial_pose"].unit == "m, rad"              # "x0 = [x, y, z, a, b, c] [m, rad]": the last brackets
    jc = {s.name: s for s in MODULES["joint_command"].parameters(MINI)}
    assert jc["force_tolerance"].unit == "N"                 # "beyond [f_min, f_max] tolerated ... [N]"


@pytest.mark.parametrize("node, cls_name, overrides", [
    ("force_distribution", "ForceDistributionNode", [Parameter("guiding_controller", value="admittance_controller")]),
    ("joint_command", "JointCommandNode", [Parameter("offset_inputs", value=["ospc", "hybrid_force_controller"])]),
    ("cable_force_controller", "CableForceControllerNode", [])])
def test_a_node_declares_exactly_its_list(node, cls_name, overrides):
    """The read-only parameters read ahead of the set (declare) and the live ones: each once, with
    the declaration's descriptor (what `ros2 param describe` shows)."""
    rclpy.init()
    try:
        instance = getattr(MODULES[node], cls_name)(parameter_overrides=[Parameter("robot", value="ipanema3_mini")] + overrides)
        try:
            extra = {p.name: p.value for p in overrides}
            specs = MODULES[node].parameters(MINI, *([extra["offset_inputs"]] if "offset_inputs" in extra else []))
            expected = {s.name: s for s in (*COMMON_PARAMS, *specs)}
            assert set(instance._parameters) - {"use_sim_time", "start_type_description_service"} == set(expected)
            for name, spec in expected.items():
                d = instance.describe_parameter(name)
                assert (d.description, d.read_only) == (spec.description, spec.read_only), name
                if spec.range is not None:
                    r = (d.integer_range or d.floating_point_range)[0]
                    assert (r.from_value, r.to_value) == spec.range, name
                assert instance.get_parameter(name).value == extra.get(name, spec.default), name
        finally:
            instance.destroy_node()
    finally:
        rclpy.shutdown()


def test_the_loop_takes_T_MA_from_the_cable_force_controller_like_the_graph(monkeypatch):
    """The CFC node's T_MA (its input's moving average under hybrid force control, 5.1.2) was
    ignored by control_loop_params, which kept HPFCParams' default: equal only while the files
    said 2.0 s."""
    from cdpr_control.control import params

    file = {"cable_force_controller": {"T_MA": 3.5}, "hybrid_force_controller": {"K_p": 1000.0}}
    monkeypatch.setattr(params, "load_params_file", lambda name: file)
    loop = params.control_loop_params("ipanema3_mini")
    assert loop.hpfc.T_MA == 3.5 and loop.hpfc.K_p == 1000.0
    del file["hybrid_force_controller"]          # no hybrid force control in the loop: nothing to set
    assert params.control_loop_params("ipanema3_mini").hpfc is None
    assert stage_field("cable_force_controller", "T_MA") == "hpfc.T_MA"


def test_the_set_refuses_what_the_declarations_exclude():
    """Sizes and finite floats come from the declarations (ParameterSet), for every node: a refused
    change says why and keeps the old value."""
    from cdpr_control.ros.parameters import ParameterSet, ParamSpec

    rclpy.init()
    try:
        node = rclpy.create_node("declarations")
        applied = []
        ParameterSet(node, [ParamSpec("v", [0.0, 0.0, 1.0], "a direction [-]", size=3),
                            ParamSpec("h", 0.0, "a height without a range [m]")], lambda v: None, applied.append)
        for name, value, reason in (("v", [0.0, 1.0], "needs 3 values"), ("v", [0.0, float("nan"), 1.0], "finite"),
                                    ("h", float("inf"), "finite"), ("h", float("nan"), "finite")):
            result = node.set_parameters([Parameter(name, value=value)])[0]
            assert not result.successful and reason in result.reason, (name, value, result.reason)
        assert list(node.get_parameter("v").value) == [0.0, 0.0, 1.0] and node.get_parameter("h").value == 0.0
        assert node.set_parameters([Parameter("h", value=-2.5)])[0].successful and applied[-1]["h"] == -2.5
        node.destroy_node()
    finally:
        rclpy.shutdown()


ROBOT_FILE = {"f_min", "f_max", "mu", "sigma", "F_pv"}      # defaults of the robot file, not of a dataclass


@pytest.mark.parametrize("node", sorted(MODULES))
def test_every_parameter_that_sets_a_field_has_its_default(node):
    """One place per default: a parameter that sets a configuration field (a stage's or a loop
    switch) declares that field's default (control.params.default)."""
    from cdpr_control.control.params import default

    for spec in MODULES[node].parameters(MINI):
        if stage_field(node, spec.name) and spec.name not in ROBOT_FILE:
            assert spec.default == default(node, spec.name), (node, spec.name)

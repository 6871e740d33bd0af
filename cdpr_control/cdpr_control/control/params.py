"""The controller's parameters: the stage dataclasses hold every default, the per-robot parameter
files ``params/<robot>.yaml`` (ROS 2 layout, the files the node graph loads) hold each robot's
tuning on top of them.

One source of truth per value: the nodes declare their parameters with the dataclass defaults
(:data:`DEFAULTS`), and :func:`control_loop_params` reads the same robot file into the
:class:`~cdpr_control.control.loop.ControlLoopParams` of the single-process loop, so the closed-loop
tests, the benchmarks and the node graph run one configuration.
"""
from __future__ import annotations

from dataclasses import fields, replace
from importlib import resources

import numpy as np
import yaml

from cdpr_control.control.cable_force_control import CFCParams
from cdpr_control.control.loop import ControlLoopParams
from cdpr_control.control.force_setpoint import ForceSetpointParams
from cdpr_control.control.friction_compensation import FrictionCompensationParams
from cdpr_control.control.ospc import OSPCParams
from cdpr_control.control.safety import SafetyConfig

# node name -> (ControlLoopParams field, dataclass) whose fields the node's parameters of the
# same name set
STAGES = {
    "cable_force_controller": ("cfc", CFCParams),
    "ospc": ("ospc", OSPCParams),
    "force_distribution": ("force", ForceSetpointParams),
    "friction_compensation": ("friction", FrictionCompensationParams),
    "joint_command": ("safety", SafetyConfig),
}
# node parameters that are loop switches rather than dataclass fields
SWITCHES = {("cable_force_controller", "enabled"): "cfc_enabled", ("ospc", "enabled"): "ospc_enabled",
            ("joint_command", "mode"): "mode",
            # the start-up calibration window of forward_kinematics and cable_force_controller
            ("/**", "calibration_window"): "calibration_window"}

DEFAULTS = {node: cls() for node, (_, cls) in STAGES.items()}


def default(node: str, name: str):
    """The library default of a node parameter, as a ROS parameter value (lists for arrays)."""
    value = getattr(DEFAULTS[node], name)
    return value.tolist() if isinstance(value, np.ndarray) else value


def params_file(robot_name: str):
    """The shipped parameter file of a robot (a Traversable), or None."""
    path = resources.files("cdpr_control").joinpath("params", f"{robot_name}.yaml")
    return path if path.is_file() else None


def load_params_file(robot_name: str) -> dict:
    """node name -> {parameter: value} of the robot's parameter file ({} without one); "/**": every node's."""
    path = params_file(robot_name)
    if path is None:
        return {}
    doc = yaml.safe_load(path.read_text()) or {}
    return {node: (entry or {}).get("ros__parameters", {}) or {} for node, entry in doc.items()}


def control_loop_params(robot, **switches) -> ControlLoopParams:
    """ControlLoopParams of the robot's parameter file over the dataclass defaults.

    robot: a Robot (its file name is the robot name) or a robot name. ``switches`` (mode,
    cfc_enabled, ospc_enabled, transfer_time) override the file.
    """
    name = robot if isinstance(robot, str) else robot.file.stem
    loop = ControlLoopParams()
    for node, values in load_params_file(name).items():
        if node in STAGES:
            attr, cls = STAGES[node]
            known = {f.name for f in fields(cls)}
            stage = {k: (np.asarray(v, dtype=float) if isinstance(v, list) else v)
                     for k, v in values.items() if k in known}
            loop = replace(loop, **{attr: replace(getattr(loop, attr), **stage)})
        for key, value in values.items():
            if (node, key) in SWITCHES:
                loop = replace(loop, **{SWITCHES[node, key]: value})
    return replace(loop, **switches)

"""The controller's parameters: the stage dataclasses hold every default, the per-robot parameter
files ``params/<robot>.yaml`` (ROS 2 layout, the files the node graph loads) hold each robot's
tuning on top of them.

One source of truth per value: the nodes declare their parameters with the dataclass defaults
(:func:`default`) and build the dataclass from the parameters of its field names (:func:`section`;
:func:`stage_field` names the field a node parameter sets, docs/parameters.md shows it), and :func:`control_loop_params` reads the same robot file into the
:class:`~cdpr_control.control.loop.ControlLoopParams` of the single-process loop, so the closed-loop
tests, the benchmarks and the node graph run one configuration. :func:`shipped_configuration`
adds the sections that are not stages of :class:`~cdpr_control.control.loop.ControlLoopParams`:
load compensation (an offset stage, with the force distribution's ``payload_input``) and hand
guiding (the admittance controller, a set-point source).
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from importlib import resources

import numpy as np
import yaml

from cdpr_control.control.cable_force_control import CFCParams
from cdpr_control.control.loop import ControlLoopParams
from cdpr_control.control.force_setpoint import ForceSetpointParams
from cdpr_control.control.friction_compensation import FrictionCompensationParams
from cdpr_control.control.ospc import OSPCParams
from cdpr_control.control.safety import SafetyConfig
from cdpr_control.control.admittance import AdmittanceController, settings_from
from cdpr_control.control.hybrid_force_control import HPFCParams
from cdpr_control.control.load_compensation import LoadCompensationParams, LoadCompensationStage

# node name -> (ControlLoopParams field, dataclass) whose fields the node's parameters of the
# same name set
STAGES = {
    "cable_force_controller": ("cfc", CFCParams),
    "ospc": ("ospc", OSPCParams),
    "force_distribution": ("force", ForceSetpointParams),
    "friction_compensation": ("friction", FrictionCompensationParams),
    "joint_command": ("safety", SafetyConfig),
}
# node parameters that are loop switches rather than fields of their node's dataclass ("stage.field":
# a field of another stage's, set when that stage is in the loop)
SWITCHES = {("cable_force_controller", "enabled"): "cfc_enabled", ("ospc", "enabled"): "ospc_enabled",
            # T_MA,HPFC filters the CFC's input (5.1.2): the CFC node's parameter
            ("cable_force_controller", "T_MA"): "hpfc.T_MA",
            ("joint_command", "mode"): "mode", ("joint_command", "start_ramp"): "start_ramp",
            ("joint_command", "transfer_time"): "transfer_time", ("hybrid_force_controller", "enabled"): "hpfc_enabled",
            # the start-up calibration window of forward_kinematics and cable_force_controller
            ("/**", "calibration_window"): "calibration_window"}

# the stages of the shipped configuration outside ControlLoopParams' STAGES (ShippedConfiguration,
# ControlLoopParams.hpfc), likewise set by the node parameters of their field names
SECTIONS = {**STAGES, "hybrid_force_controller": ("hpfc", HPFCParams),
            "load_compensation": ("load_compensation", LoadCompensationParams)}
DEFAULTS = {node: cls() for node, (_, cls) in SECTIONS.items()}
_BY_ATTR = {attr: DEFAULTS[node] for node, (attr, _) in SECTIONS.items()}    # "hpfc" -> HPFCParams()
_LOOP = ControlLoopParams()


def default(node: str, name: str):
    """The library default of a node parameter, as a ROS parameter value (lists for arrays): its
    stage dataclass field's, or for a loop switch (SWITCHES) ControlLoopParams' field."""
    field = SWITCHES.get((node, name)) or SWITCHES.get(("/**", name))
    if field is None:
        value = getattr(DEFAULTS[node], name)
    else:
        attr, _, field = field.rpartition(".")
        value = getattr(_BY_ATTR[attr] if attr else _LOOP, field)
    return value.tolist() if isinstance(value, np.ndarray) else value


def stage_field(node: str, name: str) -> str:
    """The configuration field a node parameter sets ("cfc.K_p", "cfc_enabled"), "" for none."""
    switch = SWITCHES.get((node, name)) or SWITCHES.get(("/**", name))
    if switch:
        return switch
    attr, cls = SECTIONS.get(node, (None, None))
    return f"{attr}.{name}" if cls is not None and name in {f.name for f in fields(cls)} else ""


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


def section(cls, values: dict):
    """An instance of the dataclass cls from the parameters of its node that it has fields for
    (lists as float arrays); the node's other parameters are left out."""
    known = {f.name for f in fields(cls)}
    return cls(**{k: (np.asarray(v, dtype=float) if isinstance(v, list) else v) for k, v in values.items() if k in known})


def control_loop_params(robot, **switches) -> ControlLoopParams:
    """ControlLoopParams of the robot's parameter file over the dataclass defaults, the hybrid
    position/force control (section 5.1) included when the file has its section.

    robot: a Robot (its file name is the robot name) or a robot name. ``switches`` (mode,
    cfc_enabled, ospc_enabled, transfer_time, hpfc_enabled ...) override the file.
    """
    name = robot if isinstance(robot, str) else robot.file.stem
    loop = ControlLoopParams()
    file = load_params_file(name)
    if "hybrid_force_controller" in file:
        values = file["hybrid_force_controller"]
        loop = replace(loop, hpfc=section(HPFCParams, values))     # (its enabled: SWITCHES)
    for node, values in file.items():
        if node in STAGES:
            attr, cls = STAGES[node]
            loop = replace(loop, **{attr: section(cls, values)})
        for key, value in values.items():
            if (node, key) in SWITCHES:
                loop = _set(loop, SWITCHES[node, key], value)
    return replace(loop, **switches)


def _set(loop: ControlLoopParams, field: str, value) -> ControlLoopParams:
    """loop with the switch or the "stage.field" set (a stage not in the loop: unchanged)."""
    attr, _, name = field.rpartition(".")
    if not attr:
        return replace(loop, **{name: value})
    stage = getattr(loop, attr)
    return loop if stage is None else replace(loop, **{attr: replace(stage, **{name: value})})


@dataclass
class ShippedConfiguration:
    """Everything a robot's parameter file configures for the in-process loop."""

    dt: float                                   # s, control period ("/**" control_period)
    loop: ControlLoopParams                     # the stages of Fig. 3.4 and the contact control (5.1)
    load_compensation: LoadCompensationParams   # section 4.1 (its ``enabled``: x_d,LC in the joint command)
    payload_input: bool                         # force_distribution: the identified payload as the known
                                                # part of the disturbance (3.24), docs/load_compensation.md
    admittance: dict                            # flat admittance_controller parameters (section 5.2)
    hand_guiding: bool                          # the admittance controller is the set-point source

    def offset_stages(self, robot) -> dict:
        """The offset stages of the shipped graph's joint command besides OSPC and HPFC."""
        return {"load_compensation": LoadCompensationStage(robot, self.dt, self.load_compensation,
                                                           feed_force_setpoint=self.payload_input)}

    def admittance_controller(self, robot, overrides: dict | None = None) -> AdmittanceController:
        """The hand-guiding controller of the file (``overrides``: further flat parameters)."""
        params, zones, loaded = settings_from({**self.admittance, **(overrides or {})}, robot)
        return AdmittanceController(loaded, self.dt, params, zones)


def shipped_configuration(robot, **switches) -> ShippedConfiguration:
    """The complete configuration of the robot's parameter file (missing sections: the library
    defaults); ``switches`` go to :func:`control_loop_params`."""
    name = robot if isinstance(robot, str) else robot.file.stem
    file = load_params_file(name)
    admittance = dict(file.get("admittance_controller", {}))
    return ShippedConfiguration(
        dt=float(file.get("/**", {}).get("control_period", 1e-3)),
        loop=control_loop_params(robot, **switches),
        load_compensation=section(LoadCompensationParams, file.get("load_compensation", {})),
        payload_input=bool(file.get("force_distribution", {}).get("payload_input", False)),
        admittance={k: v for k, v in admittance.items() if k != "hand_guiding"},
        hand_guiding=bool(admittance.get("hand_guiding", False)))

"""Declaring node parameters with descriptors, validating changes as a whole, applying them live.

Every cdpr node describes its parameters as a list of :class:`ParamSpec` and hands them to
:class:`ParameterSet` together with two callables: ``validate(values)`` raises ``ValueError(reason)``
for a combination it refuses (the node keeps running with its old values and the caller of
``ros2 param set`` / ``cdpr param set`` sees the reason), ``apply(values)`` makes an accepted
combination effective without restarting the node. Ranges are rclpy descriptors, so the standard
tools show them (``ros2 param describe``) and rclpy refuses out-of-range values itself.

One declaration per parameter: a node module's ``parameters(robot)`` lists every parameter of the
node once (name, type and default, range or choices, unit, description, read-only); a stage
parameter takes its default from the stage dataclass (``cdpr_control.control.params.default``) and
sets the dataclass field of its name (:func:`cdpr_control.control.params.section`). The node hands
the whole list to :class:`ParameterSet`; a read-only parameter that the node needs before its set is
built (a subscription's topic) is read first with :func:`declare`, and the set does not declare it
again. docs/parameters.md is generated from the same lists (:func:`markdown_table`,
``scripts/parameter_table.py``).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Callable

from cdpr_control.control.params import stage_field
from cdpr_control.model.calibration import DEFAULT_WINDOW, StartupCalibration
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult


_UNIT = re.compile(r"\[([^\]]*)\]")


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: object                      # float, int, bool, str or list of float
    description: str                     # meaning, the unit in brackets ("[N s/m]"), the equation
    range: tuple | None = None           # (min, max) for float or int parameters
    choices: tuple | None = None         # allowed strings
    read_only: bool = False              # fixed after start-up (e.g. the robot)
    size: int | None = None              # the length of an array parameter, where it has one

    @property
    def unit(self) -> str:
        """The unit the description gives in its last brackets ("[-]" for none), "" where it gives
        none (a switch, a name); earlier brackets are the quantity's ("[x, y, z, a, b, c] [m, rad]")."""
        units = _UNIT.findall(self.description)
        return units[-1] if units else ""

    @property
    def type_name(self) -> str:
        """The ROS parameter type of the default (bool, integer, double, string, double_array ...)."""
        value = self.default
        if isinstance(value, (list, tuple)):
            kinds = {_type_name(v) for v in value} or {"double"}
            return (kinds.pop() if len(kinds) == 1 else "double") + "_array"
        return _type_name(value)

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(description=self.description, read_only=self.read_only)
        if self.range is not None:
            lo, hi = self.range
            if isinstance(self.default, int) and not isinstance(self.default, bool):
                d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
            else:
                d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
        if self.choices:
            d.additional_constraints = "one of: " + ", ".join(self.choices)
        return d


def _type_name(value) -> str:
    return {bool: "bool", int: "integer", float: "double", str: "string"}[type(value)]


def declare(node, spec: ParamSpec):
    """Declare one parameter of the node's list ahead of its :class:`ParameterSet`; its value."""
    node.declare_parameter(spec.name, spec.default, spec.descriptor())
    return node.get_parameter(spec.name).value


class ParameterSet:
    """The declared parameters of one node and their current values (``values[name]``)."""

    def __init__(self, node, specs: list[ParamSpec], validate: Callable[[dict], None],
                 apply: Callable[[dict], None]):
        self.node = node
        self.specs = {s.name: s for s in specs}
        self._validate = validate
        self._apply = apply
        for spec in specs:
            if not node.has_parameter(spec.name):        # (read ahead with declare())
                node.declare_parameter(spec.name, spec.default, spec.descriptor())
        self.values = {s.name: node.get_parameter(s.name).value for s in specs}
        self._check(self.values)                 # a bad parameter file fails at start-up, loudly
        node.add_on_set_parameters_callback(self._on_set)
        node.add_post_set_parameters_callback(self._post_set)
        self._apply(dict(self.values))

    def _check(self, values: dict) -> None:
        """What the declarations say (choices, sizes, finite floats: no NaN reaches a stage), then
        the node's validate."""
        for name, spec in self.specs.items():
            value = values[name]
            if spec.choices and value not in spec.choices:
                raise ValueError(f"{name} must be one of {', '.join(spec.choices)}, got {value!r}")
            items = [value] if isinstance(value, (bool, int, float, str)) else list(value)
            if spec.size is not None and len(items) != spec.size:
                raise ValueError(f"{name} needs {spec.size} values, got {len(items)}")
            if not all(math.isfinite(v) for v in items if isinstance(v, float)):
                raise ValueError(f"{name} must be finite, got {items if len(items) > 1 else value!r}")
        self._validate(values)

    def _on_set(self, parameters) -> SetParametersResult:
        candidate = dict(self.values)
        for p in parameters:
            if p.name in self.specs:
                candidate[p.name] = p.value
        try:
            self._check(candidate)
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _post_set(self, parameters) -> None:
        changed = False
        for p in parameters:
            if p.name in self.specs:
                self.values[p.name] = p.value
                changed = True
        if changed:
            self._apply(dict(self.values))


def markdown_table(node: str, specs) -> str:
    """The parameters of a node as a Markdown table (docs/parameters.md): ``sets`` is the stage
    field a parameter sets (:func:`cdpr_control.control.params.stage_field`)."""
    rows = ["| name | type | default | range | unit | read-only | sets | description |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for s in specs:
        limits = f"{s.range[0]!r} .. {s.range[1]!r}" if s.range else " / ".join(s.choices or ())
        field = stage_field(node, s.name)
        cells = (f"`{s.name}`", s.type_name + (f"[{s.size}]" if s.size is not None else ""), f"`{s.default!r}`", limits, s.unit, "yes" if s.read_only else "",
                 f"`{field}`" if field else "", s.description)
        rows.append("| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |")
    return "\n".join(rows) + "\n"


def calibration_params(m: int) -> list[ParamSpec]:
    """The start-up calibration of Δq_0 (3.9), (3.23) (:mod:`cdpr_control.model.calibration`), read-only:
    the forward kinematics and the cable force controller take the same values."""
    return [
        ParamSpec("calibration_window", DEFAULT_WINDOW, "samples averaged for the start-up Δq_0 (3.9), (3.23) "
                  "when no home calibration is given (a start at home) [-]", range=(1, 100000), read_only=True),
        ParamSpec("home_forces", [0.0] * m, "home calibration: the forces at the platform [N], one per cable, "
                  "recorded when the encoders were set at home (2.3.2); Δq_0 from them wherever the controller "
                  "starts. All zero: none, the start-up window", read_only=True),
    ]


def startup_calibration(robot, v: dict) -> StartupCalibration:
    """The calibration the values of :func:`calibration_params` describe (ValueError if invalid)."""
    calibration = StartupCalibration(int(v["calibration_window"]))
    f_home = [float(f) for f in v["home_forces"]]
    if any(f_home):
        calibration.set_home(robot, f_home)
    return calibration

"""Declaring node parameters with descriptors, validating changes as a whole, applying them live.

Every cdpr node describes its parameters as a list of :class:`ParamSpec` and hands them to
:class:`ParameterSet` together with two callables: ``validate(values)`` raises ``ValueError(reason)``
for a combination it refuses (the node keeps running with its old values and the caller of
``ros2 param set`` / ``cdpr param set`` sees the reason), ``apply(values)`` makes an accepted
combination effective without restarting the node. Ranges are rclpy descriptors, so the standard
tools show them (``ros2 param describe``) and rclpy refuses out-of-range values itself.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from cdpr_control.model.calibration import DEFAULT_WINDOW, StartupCalibration
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: object                      # float, int, bool, str or list of float
    description: str                     # meaning and unit
    range: tuple | None = None           # (min, max) for float or int parameters
    choices: tuple | None = None         # allowed strings
    read_only: bool = False              # fixed after start-up (e.g. the robot)

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


class ParameterSet:
    """The declared parameters of one node and their current values (``values[name]``)."""

    def __init__(self, node, specs: list[ParamSpec], validate: Callable[[dict], None],
                 apply: Callable[[dict], None]):
        self.node = node
        self.specs = {s.name: s for s in specs}
        self._validate = validate
        self._apply = apply
        for spec in specs:
            node.declare_parameter(spec.name, spec.default, spec.descriptor())
        self.values = {s.name: node.get_parameter(s.name).value for s in specs}
        self._check(self.values)                 # a bad parameter file fails at start-up, loudly
        node.add_on_set_parameters_callback(self._on_set)
        node.add_post_set_parameters_callback(self._post_set)
        self._apply(dict(self.values))

    def _check(self, values: dict) -> None:
        for name, spec in self.specs.items():
            if spec.choices and values[name] not in spec.choices:
                raise ValueError(f"{name} must be one of {', '.join(spec.choices)}, got {values[name]!r}")
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

"""Offset inputs of the joint command: the x_* terms of (5.1)/(5.10) summed in the IK argument.

    θ_d = IK{x_d + x_OSPC + x_LC + x_HPFC} - Δq_CFC

Each controller that corrects the set-point in operational space (OSPC (3.16), load compensation
(4.6), hybrid position/force control (5.1)) is one *offset input* (admittance control (5.10)
instead becomes the set-point x_d itself while hand guiding, docs/admittance.md): a
6-vector [m, m, m, rad, rad, rad] in the base frame, published every control period with a flag
saying whether it is active. The joint command treats them all alike:

- an input counts only while it is enabled here and active at its source, and its value is finite;
- a switch on or off is ramped: the contribution is α·x with α slewing between 0 and 1 in
  ``ramp_time`` (switching off ramps the last active value out), so a controller switched live
  never steps the command (bumpless transfer);
- an active input older than its ``deadline`` is a fault that holds the command: its producer
  stopped, and adding an old correction to a moving set-point would be wrong. An inactive input
  may go silent (it contributes nothing).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdpr_control.control.safety import NON_FINITE, STALE_INPUT, Fault, all_finite


@dataclass
class OffsetSample:
    """What the producer of one offset input said for a period."""
    t: float                     # stamp [s]
    active: bool                 # the producer's own enable (e.g. ControllerState.enabled)
    x: np.ndarray                # offset [m, m, m, rad, rad, rad]


@dataclass
class OffsetConfig:
    enabled: bool = True         # taken into the sum (the joint command's switch for this input)
    deadline: float = 0.005      # age of an active sample that is a fault [s]

    def validate(self, name: str) -> None:
        if not self.deadline > 0.0:
            raise ValueError(f"offset input {name}: deadline must be > 0 s, got {self.deadline}")


class OffsetInputs:
    """The sum of the offset inputs with per-input enable, deadline and ramped switching."""

    def __init__(self, names, dt: float, ramp_time: float, configs: dict | None = None):
        names = list(names)
        if len(set(names)) != len(names):
            raise ValueError(f"offset inputs must be unique, got {names}")
        self.names = names
        self.dt = dt
        self.ramp_time = ramp_time
        self.configs = {n: OffsetConfig() for n in names}
        self.configure(configs or {}, ramp_time)
        self.alpha = dict.fromkeys(names, 0.0)
        self.last = {n: [0.0] * 6 for n in names}      # the last active value of each, as floats

    def configure(self, configs: dict, ramp_time: float) -> None:
        """Apply per-input configs (``{name: OffsetConfig}``) and the ramp time, validated first."""
        unknown = set(configs) - set(self.names)
        if unknown:
            raise ValueError(f"unknown offset inputs {sorted(unknown)}; declared: {self.names}")
        if ramp_time < 0.0:
            raise ValueError(f"offset ramp time must be >= 0 s, got {ramp_time}")
        for name, config in configs.items():
            config.validate(name)
        self.configs.update(configs)
        self.ramp_time = ramp_time

    def reset(self) -> None:
        """Forget every contribution (e.g. when the joint command leaves force control)."""
        for name in self.names:
            self.alpha[name] = 0.0
            self.last[name] = [0.0] * 6

    def update(self, now: float, samples: dict[str, OffsetSample | None]) -> tuple[np.ndarray, list[Fault]]:
        """One period: the summed offset and the faults (stale or non-finite active inputs).

        The sum Σ α·x is element-wise: on plain floats (numpy's per-call cost on 6 numbers is more than
        the arithmetic), the same products and sums in the same order, so the same numbers."""
        t0 = t1 = t2 = t3 = t4 = t5 = 0.0
        faults: list[Fault] = []
        step = 1.0 if self.ramp_time == 0.0 else self.dt / self.ramp_time
        alphas, configs = self.alpha, self.configs
        for name in self.names:
            sample = samples.get(name)
            config = configs[name]
            active = config.enabled and sample is not None and sample.active
            if active:
                age = now - sample.t
                x = np.asarray(sample.x, dtype=float)
                if age > config.deadline:
                    faults.append(Fault(STALE_INPUT, f"stale input offset {name}: older than its deadline "
                                        f"{1e3 * config.deadline:.0f} ms", True))
                    active = False
                elif x.shape != (6,) or not all_finite(values := x.tolist()):
                    faults.append(Fault(NON_FINITE, f"offset {name} is not 6 finite values: {x}", True))
                    active = False
                else:
                    self.last[name] = values
            alpha = min(1.0, alphas[name] + step) if active else max(0.0, alphas[name] - step)
            alphas[name] = alpha
            if alpha:                    # (an input switched off adds nothing)
                x0, x1, x2, x3, x4, x5 = self.last[name]
                t0, t1, t2 = t0 + alpha * x0, t1 + alpha * x1, t2 + alpha * x2
                t3, t4, t5 = t3 + alpha * x3, t4 + alpha * x4, t5 + alpha * x5
        return np.array((t0, t1, t2, t3, t4, t5)), faults

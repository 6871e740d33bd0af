"""Hand guiding (thesis section 5.2) in the in-process closed loop: the robot's shipped
configuration (:func:`cdpr_control.control.params.shipped_configuration`) with the admittance
controller as the set-point source (:class:`cdpr_sim.closed_loop.HandGuiding`) and the simulated
hand (:mod:`cdpr_sim.hand`) pushing the platform in the simulator.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdpr_control.control.admittance import AdmittanceController, fitted_settings
from cdpr_control.control.admittance_zones import Clipping
from cdpr_control.control.loop import ControlLoopParams
from cdpr_control.control.params import shipped_configuration
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import ClosedLoopRun, HandGuiding, run
from cdpr_sim.hand import Hand
from cdpr_sim.simulator import SimConfig


@dataclass
class GuidingRun:
    run: ClosedLoopRun
    source: HandGuiding      # its .outputs: the AdmittanceOutput of every period
    hand: Hand
    clipping: Clipping | None   # how the zones were shrunk to fit the wrench-feasible workspace (None: as configured)
    enabled_at: float | None = None   # s: when hand guiding was switched on (None: never)


def guiding_run(segments=(), duration: float = 1.0, overrides: dict | None = None, robot_name: str = "ipanema3_mini",
                loop_params: ControlLoopParams | None = None, before_step=None, x_hold=None,
                config: SimConfig = SimConfig(), enable_at=0.0) -> GuidingRun:
    """Hand guiding enabled at ``enable_at`` [s] (or, a callable ``enable_at(k, loop, sim) -> bool``,
    in the first period it returns true: switched on by a condition, e.g. the platform having
    settled; ``GuidingRun.enabled_at`` says when), holding ``x_hold`` (default home), the hand pushing
    ``segments``, with the robot's parameter file (``overrides``: further flat
    ``admittance_controller`` parameters; ``loop_params``: instead of the file's loop).

    Away from home the zones are centred on x_hold (``zones.origin`` = x_hold - home unless
    overridden): hand guiding starts in the rest zone wherever it is switched on. The plant is
    that of ``config`` (default: the mismatched one). The loop starts with the cable forces of the
    robot file's f_min and raises them to the planned ones within about 0.4 s; switched on before,
    the tare (the thesis' w_init) is taken while they still change, and the force sensors' gain
    errors of the mismatched plant then read as a user wrench of a few N, N m (docs/admittance.md).

    Near the border of the wrench-feasible workspace, zones that would leave it are shrunk to fit
    (:func:`cdpr_control.control.admittance.fitted_settings`; how: ``GuidingRun.clipping``);
    ValueError where not even the virtual wall's reach fits.

    Each period the user's wrench w_Adm of the set-point enters the force set-point through the loop
    (``HandGuiding.w_user``, ``ControlLoop.step``'s ``w_user``: the hand's reserve from both force
    limits, so the cables keep them when the hand lets go; docs/admittance.md)."""
    robot = load_robot(robot_name)
    shipped = shipped_configuration(robot)
    x_hold = np.array(robot.home if x_hold is None else x_hold, dtype=float)
    overrides = {"zones.origin": (x_hold - robot.home).tolist(), **(overrides or {})}
    params, zones, loaded, clipping = fitted_settings({**shipped.admittance, **overrides}, robot)
    controller = AdmittanceController(loaded, shipped.dt, params, zones)
    source, hand = HandGuiding(controller, x_hold), Hand(list(segments))
    k_on = None if callable(enable_at) else int(round(enable_at / shipped.dt))
    when = enable_at if k_on is None else (lambda k, loop, sim: k == k_on)
    enabled_at = []

    def step(k, loop, sim):
        if not enabled_at and when(k, loop, sim):
            controller.enable()
            enabled_at.append(k * shipped.dt)
        hand.apply(sim)
        if before_step is not None:
            before_step(k, loop, sim)

    result = run(robot, source, duration, loop_params or shipped.loop, x0=x_hold, before_step=step, config=config)
    return GuidingRun(result, source, hand, clipping, enabled_at[0] if enabled_at else None)

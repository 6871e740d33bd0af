"""Cable settlement under load (section 4.1.3) from a payload run with an external pose measurement.

A cable that carries more than the force it has settled to grows by a lasting s_i (the thesis:
9.2 mm of z error left after 128 kg on the IPAnema 3). At rest the cable's unstretched length is
IK{x}_i - e_i(f_i) (2.14), (2.17) up to the encoder reading theta_i and a constant offset, so

    s_i(t) = [IK{x(t)}_i - theta_i(t) - e_i(f_i(t))] - [the same before the payload],

with x the tracker's pose (``ground_truth/pose``) and f the sensor forces through the friction
compensation. The fit is :class:`cdpr_control.control.load_compensation.SettlementModel` run on the measured
forces: s_i grows towards ratio * l_t,i (f_i - f_settled,i) / k0 with time constant T and never
shrinks; s is proportional to ratio, so ratio is linear least squares for each T of a grid and T the
best of the grid. k0 and l_t are the robot file's: identify the stiffness first and pass that robot
(the ratio is relative to the model the load compensation runs on). The forces at the sensors and
the pose are not enough without the tracker: the weight of the payload fixes the forces, and the
sinking platform changes them only through the cable directions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdpr_control.model import cable
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.control.load_compensation import SettlementModel

from cdpr_tools.identify import bag_data


@dataclass
class SettlementFit:
    ratio: float              # -, settlement strain per elastic strain of the extra force
    T: float                  # s, time constant
    s_final: np.ndarray       # (m,) m, measured lasting growth at the end of the run
    rms: float                # m, residual
    n_samples: int


def identify(bag, robot, friction_params: dict | None = None, rest: float = 0.4, f_taut: float = 1.0,
             T_grid=None) -> SettlementFit:
    """Fit ratio and T of the settlement model to ``bag`` (:func:`experiments.record_settlement_run`);
    the first ``rest`` s (before the payload) are the settled reference."""
    from cdpr_tools.identify.friction import load_data
    from cdpr_tools.identify.mass import compensated_forces

    data = load_data(bag, robot)
    dt = float(np.median(np.diff(data.t)))
    f = compensated_forces(robot, data, dt, friction_params)
    x = bag_data.poses(bag, data.t)
    q = np.array([inverse_kinematics(robot, xk).q for xk in x])
    l_t = cable.total_free_length(robot, q)
    u = q - data.theta - cable.elongation_from_force(robot, np.maximum(f, 0.0), l_t)   # unstretched length + const
    ref = data.t - data.t[0] < rest
    if ref.sum() < 10:
        raise ValueError("the run needs at least 10 samples before the payload (rest)")
    s_meas = u - u[ref].mean(axis=0)
    use = (~ref)[:, None] & (f >= f_taut)
    T_grid = np.geomspace(0.2, 20.0, 41) if T_grid is None else np.asarray(T_grid, dtype=float)
    model = SettlementModel(robot, dt, ratio=1.0, T=T_grid[:, None])       # all T of the grid at once
    model.reset(f[ref].mean(axis=0))
    s_unit = np.array([model.update(fk, lk) for fk, lk in zip(f, l_t)])     # (N, len(T_grid), m), ratio 1
    b = s_meas[use]
    best = None
    for j, T in enumerate(T_grid):
        a = s_unit[:, j][use]
        ratio = max(float(a @ b / (a @ a)), 0.0) if a @ a > 0.0 else 0.0
        rms = float(np.sqrt(np.mean((ratio * a - b) ** 2)))
        if best is None or rms < best[2]:
            best = (ratio, float(T), rms)
    end = data.t > data.t[-1] - 0.2
    return SettlementFit(best[0], best[1], s_meas[end].mean(axis=0), best[2], int(use.any(axis=1).sum()))

"""Energy consumption model of the actuator units, thesis section 4.4.1, (4.9)-(4.14), table 4.6.

Per cable, from the platform to the mains (Fig. 4.29):

* pulleys (4.9): the force at the platform f is given, the force at the drum f_w follows by solving
  the Coulomb and viscous pulley model (3.35) backwards over every pulley from the platform to the
  sensor pulley with the energy section's mu and F_pv (table 4.6) and the pulley geometry of the
  robot file's friction section; as in the thesis the Dahl hysteresis is left out and f_w = F_1 (3.40).
* winch (4.10)-(4.11): alphadot = thetadot / r_w and the motor torque
  tau = r_w f_w - J_w alphaddot - (r_w f_w mu_w + (F_s - r_w f_w mu_w) e^(-|alphadot|/alphadot_s))
  sgn(alphadot) - F_wv alphadot.
* servo drive (4.12): DC-link power of the drive from its shaft power, copper, re-magnetisation
  and eddy current losses.
* control cabinet (4.13)-(4.14): DC-link exchange between the drives, idle power P_0 and the
  supply efficiencies in motor and generator operation.

Signs: thetadot > 0 pays cable out (the project's convention, friction.py). tau of (4.11) is the
torque the motor holds against the cable (positive under tension), so tau alphadot is the power
flowing from the cable into the motor shaft, P_s of (4.15) (> 0 while the load drives the winch,
generator operation). P_DC > 0 draws power from the DC link.

Where this module departs from the printed equations, and why (docs/analysis.md):

* (4.12) prints P_DC = c_m alphadot tau + ...: with P_s = tau alphadot of (4.15) that sign makes a
  lowering load draw power. The shaft power enters as -P_s, and the amplifier efficiency c_m
  divides it in motor operation and multiplies it in generator operation (as printed, c_m < 1
  would make the amplifier deliver more shaft power than it draws, a negative loss).
* The re-magnetisation losses of (4.12) scale with |alphadot| (printed c_n1 alphadot, which would
  turn into a gain when the motor turns backwards).
* (4.14) prints P_0 + sum P_DC c_p,m in motor operation; the supply draws sum P_DC / c_p,m from
  the mains (efficiency c_p,m < 1), and feeds back sum P_DC c_p,g in generator operation.

With these, the power balance closes exactly:
P_el = P_mech + P_pulley + P_winch + P_inertia + P_servo + P_cabinet, with P_mech = -sum f thetadot
the power the cables deliver to the platform and every loss term >= 0 (:class:`PowerFlow`).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from cdpr_control.model.friction import wrap_factor


def _params(robot):
    if robot.energy is None:
        raise ValueError(f"{robot.file}: the robot file has no 'energy' section (thesis table 4.6)")
    return robot.energy


def pulley_force_before(F_j, thetadot, mu, F_pv, beta) -> np.ndarray:
    """F_{j-1} (4.9): the force before a pulley (drum side) from the force after it, (3.34) solved."""
    F_j, thetadot = np.asarray(F_j, dtype=float), np.asarray(thetadot, dtype=float)
    smk = np.sign(thetadot) * mu * wrap_factor(beta)
    return (F_j * (2.0 - smk) - 2.0 * F_pv * thetadot) / (2.0 + smk)


def drum_force(robot, f, thetadot, beta_last) -> np.ndarray:
    """f_w (..., m) at the drum from the force at the platform f: (4.9) for every pulley from the
    platform, first the swivelling pulley (wrap angle beta_last (..., m) from the IK (2.6)), then
    the fixed inner pulleys (robot.friction: n_pulleys, beta_inner); f_w = F_1 (3.40)."""
    e, fr = _params(robot), robot.friction
    F = pulley_force_before(f, thetadot, e.pulley_mu, e.pulley_F_pv, beta_last)
    F = np.where(fr.n_pulleys >= 2, F, f)
    for j in range(int(fr.n_pulleys.max()) - 2):
        inner = j < fr.n_pulleys - 2
        F = np.where(inner, pulley_force_before(F, thetadot, e.pulley_mu, e.pulley_F_pv, fr.beta_inner), F)
    return F


def motor_speed(robot, thetadot) -> np.ndarray:
    """alphadot = thetadot / r_w (4.10) [rad/s]."""
    return np.asarray(thetadot, dtype=float) / _params(robot).r_w


def winch_friction_torque(robot, f_w, alphadot) -> np.ndarray:
    """Magnitude of the winch friction of (4.11): Coulomb with Stribeck, plus viscous [N m] (>= 0 moving).

    (r_w f_w mu_w + (F_s - r_w f_w mu_w) e^(-|alphadot| / alphadot_s)) + F_wv |alphadot|, zero at rest.
    """
    e = _params(robot)
    alphadot = np.asarray(alphadot, dtype=float)
    coulomb = e.r_w * np.asarray(f_w, dtype=float) * e.mu_w
    stribeck = coulomb + (e.F_s - coulomb) * np.exp(-np.abs(alphadot) / e.alphadot_s)
    return np.where(alphadot != 0.0, stribeck, 0.0) + e.F_wv * np.abs(alphadot)


def motor_torque(robot, f_w, alphadot, alphaddot) -> np.ndarray:
    """tau (4.11) [N m]: the torque the motor holds against the cable force f_w at the drum."""
    e = _params(robot)
    alphadot = np.asarray(alphadot, dtype=float)
    return (e.r_w * np.asarray(f_w, dtype=float) - e.J_w * np.asarray(alphaddot, dtype=float)
            - np.sign(alphadot) * winch_friction_torque(robot, f_w, alphadot))


def servo_losses(robot, tau, alphadot) -> tuple[np.ndarray, np.ndarray]:
    """(amplifier, motor) losses of (4.12) [W], both >= 0.

    Amplifier: shaft power -tau alphadot divided by c_m in motor, multiplied in generator operation.
    Motor: copper 3 (tau / Psi_m)^2 R, re-magnetisation c_n1 |alphadot|, eddy currents c_n2 alphadot^2.
    """
    e = _params(robot)
    tau, alphadot = np.asarray(tau, dtype=float), np.asarray(alphadot, dtype=float)
    P_out = -tau * alphadot
    amplifier = np.where(P_out >= 0.0, P_out * (1.0 / e.c_m - 1.0), -P_out * (1.0 - e.c_m))
    motor = 3.0 * (tau / e.Psi_m) ** 2 * e.R + e.c_n1 * np.abs(alphadot) + e.c_n2 * alphadot**2
    return amplifier, motor


def dc_power(robot, tau, alphadot) -> np.ndarray:
    """P_DC (4.12) [W] of each drive: shaft power -tau alphadot plus the servo losses (> 0 draws power)."""
    amplifier, motor = servo_losses(robot, tau, alphadot)
    return -np.asarray(tau, dtype=float) * np.asarray(alphadot, dtype=float) + amplifier + motor


def dc_link_recovery(P_DC) -> np.ndarray:
    """P_DC,rec = sum |P_DC,i| - |sum P_DC,i| (4.13) [W]: power exchanged between the drives."""
    P_DC = np.asarray(P_DC, dtype=float)
    return np.abs(P_DC).sum(axis=-1) - np.abs(P_DC.sum(axis=-1))


def electrical_power(robot, P_DC) -> np.ndarray:
    """P_el (4.14) [W] at the cabinet input from the drives' P_DC (..., m).

    P_0 + sum P_DC / c_p,m while the drives draw power, P_0 + sum P_DC c_p,g while they feed back.
    """
    e = _params(robot)
    total = np.asarray(P_DC, dtype=float).sum(axis=-1)
    return e.P_0 + np.where(total >= 0.0, total / e.c_pm, total * e.c_pg)


@dataclass
class PowerFlow:
    """Power over time [W], (N,) sums over the cables unless noted; P_el is their exact sum.

    P_mech: delivered by the cables to the platform, -sum f thetadot (lifting > 0);
    P_pulley (4.9), P_winch (4.11, friction), P_servo (4.12), P_cabinet (4.14, idle + supply):
    losses, each >= 0; P_inertia: rate of the kinetic energy stored in the winches (J_w alphaddot
    alphadot); P_rec: DC-link exchange between the drives (4.13), not a loss; P_DC (N, m) per drive.
    """

    t: np.ndarray
    P_mech: np.ndarray
    P_pulley: np.ndarray
    P_winch: np.ndarray
    P_inertia: np.ndarray
    P_servo: np.ndarray
    P_cabinet: np.ndarray
    P_el: np.ndarray
    P_rec: np.ndarray
    P_DC: np.ndarray

    LOSSES = ("P_pulley", "P_winch", "P_servo", "P_cabinet")

    def energy(self, name: str) -> float:
        """Time integral [J] of one series (trapezoidal rule)."""
        return float(np.trapezoid(getattr(self, name), self.t))

    def energies(self) -> dict[str, float]:
        """Every series integrated [J] (P_DC summed over the drives)."""
        out = {f.name.replace("P_", "E_"): self.energy(f.name) for f in fields(self)
               if f.name not in ("t", "P_DC")}
        out["E_DC"] = float(np.trapezoid(self.P_DC.sum(axis=1), self.t))
        return out

    def loss_shares(self) -> dict[str, float]:
        """Share of each loss in the total losses (Fig. 4.31)."""
        E = {name: self.energy(name) for name in self.LOSSES}
        total = sum(E.values())
        return {name: value / total for name, value in E.items()}


def power_flow(robot, t, f, thetadot, thetaddot, beta_last) -> PowerFlow:
    """The model (4.9)-(4.14) along samples t (N,) of the platform forces f, cable velocities
    thetadot and accelerations thetaddot (N, m) and the swivelling pulleys' wrap angles beta_last.
    """
    e = _params(robot)
    f, thetadot = np.asarray(f, dtype=float), np.asarray(thetadot, dtype=float)
    f_w = drum_force(robot, f, thetadot, beta_last)                      # (4.9)
    alphadot = motor_speed(robot, thetadot)                              # (4.10)
    alphaddot = motor_speed(robot, thetaddot)
    tau = motor_torque(robot, f_w, alphadot, alphaddot)                  # (4.11)
    amplifier, motor = servo_losses(robot, tau, alphadot)                # (4.12)
    P_DC = -tau * alphadot + amplifier + motor
    P_el = electrical_power(robot, P_DC)                                 # (4.14)
    return PowerFlow(
        t=np.asarray(t, dtype=float),
        P_mech=-(f * thetadot).sum(axis=1),
        P_pulley=((f - f_w) * thetadot).sum(axis=1),
        P_winch=(winch_friction_torque(robot, f_w, alphadot) * np.abs(alphadot)).sum(axis=1),
        P_inertia=(e.J_w * alphaddot * alphadot).sum(axis=1),
        P_servo=(amplifier + motor).sum(axis=1),
        P_cabinet=P_el - P_DC.sum(axis=1),
        P_el=P_el,
        P_rec=dc_link_recovery(P_DC),                                    # (4.13)
        P_DC=P_DC,
    )


def winch_efficiency(robot, f_w, thetadot) -> np.ndarray:
    """eta_w (4.15) of the winch at steady cable velocity: (P_s / P_w)^sgn(P_w), NaN where undefined.

    P_w = f_w thetadot, P_s = tau alphadot; undefined (NaN) at rest and where the cable force cannot
    overcome the winch friction while paying out (the motor must drive, Fig. 4.32).
    """
    f_w, thetadot = np.asarray(f_w, dtype=float), np.asarray(thetadot, dtype=float)
    alphadot = motor_speed(robot, thetadot)
    P_w = f_w * thetadot
    P_s = motor_torque(robot, f_w, alphadot, 0.0) * alphadot
    with np.errstate(divide="ignore", invalid="ignore"):
        eta = np.where(P_w > 0.0, P_s / P_w, P_w / P_s)
    return np.where((P_w != 0.0) & (eta > 0.0) & np.isfinite(eta), eta, np.nan)

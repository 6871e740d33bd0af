"""The simulated robot's own parameters: a plant that is not the controller's model.

The controller works with the nominal robot file (cdpr_control/robots/<robot>.yaml). A real robot
differs from it: its frame is measured to a few millimetres, its cables are stiffer or softer and
settle under load, its pulleys have their own friction, its drives their own time constants and
dead time, its force sensors their own lines. :func:`build_plant` makes such a robot: every
parameter listed in ``plants/mismatch.yaml`` is drawn once, uniformly within the bound given there,
from a seed (``plant_seed``), so one seed is one reproducible robot. ``kind="nominal"`` is the
perfect model (the plant equals the robot file), for tests that check an equation.

What the simulator takes from the plant (and not from the robot file):

* geometry a_i, b_i, l_0 and the cable stiffness (2.16): the physics of :mod:`cdpr_sim.cables`
  (the simulator reuses ``cdpr_control.model.cable`` and ``cdpr_control.model.kinematics`` as functions, with
  these parameters);
* pulley friction mu, sigma, F_pv (3.30)-(3.43) (``cdpr_control.model.friction`` with these parameters);
* drive time constant, damping and dead time (3.10)/(5.11) (``cdpr_sim.drive_models``);
* the true sensor lines gamma_1, gamma_0 (3.29); the readings still apply the robot file's
  calibration, so the difference is a force measurement error;
* cable settlement under load (section 4.1.3), :class:`Settlement`.

The platform's mass and inertia are the robot file's: payloads the controller does not know are
set explicitly (``Simulator.set_payload``), so that experiments control them.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from cdpr_control.kernels.jit import njit
import yaml

from cdpr_control.model.robot import Robot

MISMATCH_FILE = Path(__file__).parent / "plants" / "mismatch.yaml"
KINDS = ("mismatched", "nominal")


@dataclass(frozen=True)
class Plant:
    """The simulated robot: ``robot`` its true parameters; sensor lines and settlement beside it."""

    kind: str
    seed: int
    nominal: Robot                       # the controller's robot file
    robot: Robot                         # the plant's own parameters
    gamma_1: np.ndarray                  # (m,) true sensor line slopes (3.29)
    gamma_0: np.ndarray                  # (m,) N, true sensor line offsets (3.29)
    settlement_ratio: float = 0.0        # -, see plants/mismatch.yaml
    settlement_time: float = 2.0         # s
    draws: dict = field(default_factory=dict, compare=False)   # the drawn relative errors, for reports

    def summary(self) -> dict:
        """Plant against nominal, as plain numbers: for reports and docs."""
        n, p = self.nominal, self.robot
        rel = lambda a, b: float(np.max(np.abs(np.asarray(a) / np.asarray(b) - 1.0)))  # noqa: E731
        return {
            "kind": self.kind, "seed": self.seed,
            "max |a - a_nom| [mm]": 1e3 * float(np.abs(p.a - n.a).max()),
            "max |b - b_nom| [mm]": 1e3 * float(np.abs(p.b - n.b).max()),
            "k0 / k0_nom": float(p.cable.k0 / n.cable.k0),
            "max |mu / mu_nom - 1|": rel(p.friction.mu, n.friction.mu),
            "drive T_d [ms]": 1e3 * p.drive.T_d, "nominal T_d [ms]": 1e3 * n.drive.T_d,
            "max |gamma_1 - 1|": float(np.abs(self.gamma_1 / n.sensor.gamma_1 - 1.0).max()),
            "max |gamma_0| [N]": float(np.abs(self.gamma_0 - n.sensor.gamma_0).max()),
            "settlement ratio": self.settlement_ratio,
        }


def _frozen(x) -> np.ndarray:
    """A read-only float array, as the robot file's arrays are."""
    x = np.array(x, dtype=float)
    x.setflags(write=False)
    return x


def mismatch_bounds(robot_name: str, file: Path | str = MISMATCH_FILE) -> dict:
    """The bounds of ``file`` for one robot: defaults with the robot's overrides merged in."""
    doc = yaml.safe_load(Path(file).read_text())
    bounds = copy.deepcopy(doc["defaults"])
    for group, values in ((doc.get("robots") or {}).get(robot_name) or {}).items():
        bounds.setdefault(group, {}).update(values)
    return bounds


def build_plant(robot: Robot, kind: str = "mismatched", seed: int = 1, file: Path | str | None = None) -> Plant:
    """The plant of ``robot`` (the nominal file): ``nominal`` is the robot itself, ``mismatched``
    a robot drawn within the bounds of ``file`` (default plants/mismatch.yaml) with ``seed``."""
    if kind not in KINDS:
        raise ValueError(f"plant must be one of {', '.join(KINDS)}, got {kind!r}")
    s = robot.sensor
    if kind == "nominal":
        return Plant(kind, seed, robot, robot, np.full(robot.m, s.gamma_1), np.full(robot.m, s.gamma_0))
    b = mismatch_bounds(robot.file.stem, file or MISMATCH_FILE)
    rng = np.random.Generator(np.random.PCG64(seed))
    m = robot.m
    draws: dict = {}

    def uniform(group, key, shape=()):
        value = rng.uniform(-1.0, 1.0, shape) * float(b[group][key])
        draws[f"{group}.{key}"] = value
        return value

    a = robot.a + uniform("geometry", "a", (m, 3))
    b_p = robot.b + uniform("geometry", "b", (m, 3))
    l_0 = robot.l_0 * (1.0 + uniform("geometry", "l_0", m))
    c = robot.cable
    cable = replace(c, k0=c.k0 * (1.0 + uniform("cable", "k0")), k1=c.k1 * (1.0 + uniform("cable", "k1")),
                    k2=c.k2 * (1.0 + uniform("cable", "k2")))
    fr = robot.friction
    friction = replace(fr, mu=_frozen(fr.mu * (1.0 + uniform("friction", "mu", m))),
                       sigma=_frozen(fr.sigma * (1.0 + uniform("friction", "sigma", m))),
                       F_pv=_frozen(fr.F_pv * (1.0 + uniform("friction", "F_pv", m))))
    d = robot.drive
    lo, hi = b["drive"]["extra_dead_time"]
    extra = float(rng.uniform(lo, hi))
    draws["drive.extra_dead_time"] = extra
    tc = 1.0 + uniform("drive", "time_constant")
    drive = replace(d, T_1=d.T_1 * tc, T_w=d.T_w * tc, zeta=d.zeta * (1.0 + uniform("drive", "zeta")),
                    T_d=d.T_d + extra)
    gamma_1 = s.gamma_1 * (1.0 + uniform("sensor", "gamma_1", m))
    gamma_0 = s.gamma_0 + uniform("sensor", "gamma_0", m) * s.range
    true = replace(robot, a=_frozen(a), b=_frozen(b_p), l_0=_frozen(l_0), cable=cable, friction=friction,
                   drive=drive)
    st = b["settlement"]
    return Plant(kind, seed, robot, true, gamma_1, gamma_0, float(st["ratio"]), float(st["time"]), draws)


class Settlement:
    """Cable settlement under load (section 4.1.3): a lasting growth s (m,) of the unstretched
    cable length once a cable carries more than the force it has settled to.

    s approaches ratio * l_t (f_peak - f_settled) / k0 with time constant T and never shrinks,
    f_peak the highest force so far; ratio 0 switches it off.
    """

    def __init__(self, ratio: float, T: float, k0: float, dt: float, m: int):
        if not (ratio >= 0.0 and T > 0.0 and k0 > 0.0):
            raise ValueError(f"settlement needs ratio >= 0, T > 0 s and k0 > 0 N, got {ratio}, {T}, {k0}")
        self.ratio, self.T, self.k0, self.dt = ratio, T, k0, dt
        self.alpha = 1.0 - np.exp(-dt / T)
        self.s = np.zeros(m)
        self.f_settled: np.ndarray | None = None

    def reset(self, f_settled) -> None:
        """Power-on: the cables have settled to the forces f_settled (m,)."""
        self.s[:] = 0.0
        self.f_settled = np.array(f_settled, dtype=float)

    def settle(self, f, l_t) -> None:
        """The cables have settled to the forces f (m,) they carry now at the free lengths l_t (m,),
        their lasting growth s kept: f_settled becomes the force at which the law's target is the
        present s, so s grows again only under forces above f (a robot that has stood loaded so long)."""
        if self.ratio == 0.0 or self.f_settled is None:
            return
        self.f_settled[:] = np.asarray(f, dtype=float) - self.s * self.k0 / (self.ratio * np.asarray(l_t, dtype=float))

    def update(self, f, l_t) -> np.ndarray:
        """One step with the forces f (m,) and free lengths l_t (m,) -> s (m,) [m]."""
        if self.ratio == 0.0:
            return self.s
        if self.f_settled is None:
            self.reset(f)
        settle_kernel(self.s, np.asarray(f, dtype=float), np.asarray(l_t, dtype=float), self.f_settled, self.ratio, self.k0,
                self.alpha)
        return self.s


@njit
def settle_kernel(s, f, l_t, f_settled, ratio, k0, alpha):
    """The loop of Settlement.update (once per control period: as numpy calls on m values it cost
    five times more), the same expression per cable as the array form
    s += alpha max(ratio l_t max(f - f_settled, 0) / k0 - s, 0)."""
    for i in range(s.shape[0]):
        target = ratio * l_t[i] * max(f[i] - f_settled[i], 0.0) / k0
        s[i] += alpha * max(target - s[i], 0.0)

"""Robot descriptions: the one loader for the project's robot YAML files.

A robot file holds geometry (thesis tables 2.3/2.4), cable, drive, platform, sensor and friction
parameters in SI units (keys ending in ``_deg`` are degrees and converted to rad here). Every key is
checked for presence, shape, sign and finiteness; any problem raises :class:`RobotFileError` naming
the file and the dotted key, e.g. ``ipanema3.yaml: geometry.r_p[3]: must be > 0, got -0.05``. The
file is read by :mod:`cdpr_control.model.yaml_file` (a key given twice, deep nesting and text that is not
UTF-8 are refused in words), at most MAX_CABLES cables are taken, and the home pose must lie inside
the frame and in the wrench-feasible workspace (2.39)-(2.40).

Per-cable values may be written as one scalar, which applies to every cable.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.force_distribution import quadratic_program, wrench_feasible
from cdpr_control.model.workspace import static_problem
from cdpr_control.model.yaml_file import YamlFileError, load_yaml

ROBOTS_DIR = Path(__file__).parents[1] / "robots"
MAX_VALUES = 100_000      # scalars a robot file may expand to (a YAML alias bomb is refused early)
# Cable robots are built with up to about a dozen cables (the thesis' have 8); 32 leaves room for
# research designs while a file with thousands of cables is refused before the per-cable arrays,
# the pairwise anchor check and the workspace check at home are computed.
MAX_CABLES = 32


class RobotFileError(ValueError):
    """A robot file is missing a key or holds a value of the wrong shape, sign or type."""


# --- parameter groups ------------------------------------------------------------------------


@dataclass(frozen=True)
class CableParams:
    """Cable model: specific stiffness (2.15)-(2.16) and force limits (2.39)."""

    diameter: float          # m
    k_spec_nominal: float    # N, linear specific stiffness EA
    k0: float                # N, (2.16)
    k1: float                # -, (2.16)
    k2: float                # 1/N, (2.16)
    f_min: np.ndarray        # (m,) N
    f_max: np.ndarray        # (m,) N


@dataclass(frozen=True)
class DriveParams:
    """Position-controlled winch: PT1 + dead time (3.10) or second order (5.11)."""

    model: str               # "pt1_deadtime" | "second_order"
    T_1: float               # s, PT1 time constant (3.10)
    T_d: float               # s, dead time (3.10)
    T_w: float               # s, second-order time constant (5.11)
    zeta: float              # -, second-order damping (5.11)
    v_max: float             # m/s, max cable velocity
    drum_radius: float       # m
    gear_ratio: float        # -


@dataclass(frozen=True)
class PlatformParams:
    """Rigid platform of (2.30)-(2.33)."""

    mass: float                      # kg
    center_of_gravity: np.ndarray    # (3,) m, platform frame
    inertia: np.ndarray              # (3, 3) kg m^2 about the centre of gravity, platform frame


@dataclass(frozen=True)
class SensorParams:
    """Winch-integrated force sensor, sensor line (3.29) and AD conversion (section 3.7.1)."""

    range: float             # N, full scale
    bits: int                # -, AD resolution
    noise_std: float         # N
    gamma_1: float           # -, slope of (3.29)
    gamma_0: float           # N, offset of (3.29)
    beta_1: float            # rad, wrap angle at the sensor pulley (3.36)-(3.40)


@dataclass(frozen=True)
class FrictionParams:
    """Pulley friction between sensor and platform, (3.30)-(3.43)."""

    n_pulleys: np.ndarray    # (m,) int, pulleys from sensor to platform, last one swivelling
    beta_inner: float        # rad, wrap angle of the fixed inner pulleys
    mu: np.ndarray           # (m,) -, Coulomb coefficient (3.31)
    sigma: np.ndarray        # (m,) N/m, Dahl stiffness (3.43)
    F_pv: np.ndarray         # (m,) N s/m, viscous parameter (3.31)


@dataclass(frozen=True)
class EnergyParams:
    """Energy consumption model of the actuator units, thesis (4.9)-(4.14), table 4.6."""

    pulley_mu: np.ndarray    # (m,) -, Coulomb coefficient of the pulleys (4.9)
    pulley_F_pv: np.ndarray  # (m,) N s/m, viscous pulley friction (4.9)
    r_w: float               # m, drum radius over gear ratio (4.10)
    J_w: float               # kg m^2, winch, gear box and rotor inertia at the motor (4.11)
    mu_w: float              # -, Coulomb friction coefficient of the winch (4.11)
    F_wv: float              # N m s, viscous friction (4.11)
    F_s: float               # N m, static friction (4.11)
    alphadot_s: float        # rad/s, Stribeck velocity (4.11)
    c_m: float               # -, efficiency of the servo amplifier (4.12)
    R: float                 # Ohm, winding resistance (4.12)
    Psi_m: float             # N m/A, torque constant (4.12)
    c_n1: float              # W s, re-magnetisation losses (4.12)
    c_n2: float              # W s^2, eddy current losses (4.12)
    P_0: float               # W, idle power of the control cabinet (4.14)
    c_pm: float              # -, supply efficiency in motor operation (4.14)
    c_pg: float              # -, supply efficiency in generator operation, 0 = brake resistor (4.14)


@dataclass(frozen=True)
class Robot:
    """A cable robot with m cables and n DOF; arrays are read-only, units SI."""

    name: str
    file: Path
    m: int
    n: int
    frame_size: np.ndarray           # (3,) m
    gravity: np.ndarray              # (3,) m/s^2, base frame
    home: np.ndarray                 # (6,) pose x = [m, m, m, rad, rad, rad]
    workspace_min: np.ndarray        # (3,) m
    workspace_max: np.ndarray        # (3,) m
    swivelling_pulleys: bool
    a: np.ndarray                    # (m, 3) m, base vectors a_i
    b: np.ndarray                    # (m, 3) m, platform vectors b_i
    pulley_orientation: np.ndarray   # (m, 3) rad, Kardan angles phi_A of the pulley frames
    r_p: np.ndarray                  # (m,) m, pulley radius
    l_0: np.ndarray                  # (m,) m, winch-to-pulley cable length of (2.14)
    cable: CableParams
    drive: DriveParams
    platform: PlatformParams
    sensor: SensorParams
    friction: FrictionParams
    energy: EnergyParams | None = None   # optional section ``energy`` of the robot file

    def with_payload(self, mass: float, center_of_gravity=(0.0, 0.0, 0.0), inertia=None) -> "Robot":
        """The same robot carrying a point-like (or given-inertia) payload rigidly on the platform.

        Mass adds, the centre of gravity is the mass-weighted mean and the inertia about the new
        centre of gravity follows from the parallel-axis theorem.
        """
        if not (np.isfinite(mass) and mass >= 0.0):
            raise ValueError(f"payload mass must be finite and >= 0 kg, got {mass}")
        p = self.platform
        c_l = np.asarray(center_of_gravity, dtype=float)
        I_l = np.zeros((3, 3)) if inertia is None else np.asarray(inertia, dtype=float)
        m_t = p.mass + mass
        c_t = (p.mass * p.center_of_gravity + mass * c_l) / m_t
        I_t = _shifted_inertia(p.inertia, p.mass, p.center_of_gravity - c_t) + _shifted_inertia(
            I_l, mass, c_l - c_t
        )
        platform = PlatformParams(m_t, _frozen(c_t), _frozen(I_t))
        return _replace(self, platform=platform)


def _shifted_inertia(I_c: np.ndarray, mass: float, d: np.ndarray) -> np.ndarray:
    """Parallel-axis theorem: inertia about a point displaced by -d from the centre of gravity."""
    return I_c + mass * (float(d @ d) * np.eye(3) - np.outer(d, d))


def _replace(obj, **changes):
    values = {f.name: getattr(obj, f.name) for f in fields(obj)}
    values.update(changes)
    return type(obj)(**values)


def _frozen(x: np.ndarray) -> np.ndarray:
    x = np.array(x, dtype=float)
    x.setflags(write=False)
    return x


# --- validation ------------------------------------------------------------------------------


class _Reader:
    """Reads typed values out of the parsed YAML, raising errors that name file and key."""

    def __init__(self, data: dict, file: Path):
        self.data = data
        self.file = file
        self.used: set[str] = set()          # dotted keys read, to find unknown ones

    def error(self, key: str, message: str) -> RobotFileError:
        return RobotFileError(f"{self.file}: {key}: {message}")

    def raw(self, key: str):
        node = self.data
        for part in key.split("."):
            if not isinstance(node, dict):
                raise self.error(key, f"expected a mapping above '{part}'")
            if part not in node:
                raise self.error(key, "missing key")
            node = node[part]
        self.used.add(key)
        return node

    def optional(self, key: str) -> bool:
        """Whether an optional key is present (mark it read with the typed accessors)."""
        try:
            self.raw(key)
        except RobotFileError:
            return False
        return True

    def check_unknown(self) -> None:
        """Every key of the file must have been read: a typo (``f_mx``) is an error, not a default."""
        def walk(node, prefix):
            for k, v in node.items():
                key = f"{prefix}{k}"
                if key in self.used:
                    continue
                if isinstance(v, dict) and any(u.startswith(key + ".") for u in self.used):
                    walk(v, key + ".")
                else:
                    known = sorted({u.split(".")[prefix.count(".")] for u in self.used if u.startswith(prefix)})
                    raise self.error(key, f"unknown key; known here: {', '.join(known)}")
        walk(self.data, "")

    def array(self, key: str, shape: tuple, sign: str | None = None, deg: bool = False) -> np.ndarray:
        """A float array of the given shape; a scalar broadcasts to a (m,) shape."""
        value = self.raw(key)
        if _has_bool(value):                      # YAML's true is not 1.0 m
            raise self.error(key, f"expected numbers of shape {shape}, got {_short(value)}")
        try:
            x = np.array(value, dtype=float)
        except (TypeError, ValueError):
            raise self.error(key, f"expected numbers of shape {shape}, got {_short(value)}") from None
        if x.ndim == 0 and len(shape) == 1:
            x = np.full(shape, float(x))
        if x.shape != shape:
            raise self.error(key, f"expected shape {shape}, got {x.shape}")
        self._check_sign(key, x, sign)
        return _frozen(np.deg2rad(x) if deg else x)

    def scalar(self, key: str, sign: str | None = None) -> float:
        value = self.raw(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key, f"expected a number, got {_short(value)}")
        x = np.array([float(value)])
        self._check_sign(key, x, sign)
        return float(x[0])

    def integer(self, key: str, minimum: int) -> int:
        value = self.raw(key)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise self.error(key, f"expected an integer >= {minimum}, got {_short(value)}")
        return value

    def choice(self, key: str, options: tuple) -> str:
        value = self.raw(key)
        if value not in options:
            raise self.error(key, f"expected one of {', '.join(options)}, got {_short(value)}")
        return value

    def boolean(self, key: str) -> bool:
        value = self.raw(key)
        if not isinstance(value, bool):
            raise self.error(key, f"expected true or false, got {_short(value)}")
        return value

    def _check_sign(self, key: str, x: np.ndarray, sign: str | None) -> None:
        flat = x.reshape(-1)
        for i, v in enumerate(flat):
            where = f"{key}[{i}]" if flat.size > 1 else key
            if not np.isfinite(v):
                raise self.error(where, f"must be finite, got {v}")
            if sign == "positive" and not v > 0.0:
                raise self.error(where, f"must be > 0, got {v}")
            if sign == "nonnegative" and not v >= 0.0:
                raise self.error(where, f"must be >= 0, got {v}")


def _short(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} characters)"


def _has_bool(value) -> bool:
    if isinstance(value, bool):
        return True
    return isinstance(value, list) and any(_has_bool(v) for v in value)


def _count_values(node, limit: int) -> int:
    """Scalars in a parsed YAML tree, counting shared (aliased) parts each time; stops past ``limit``."""
    count, stack = 0, [node]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
        else:
            count += 1
        if count + len(stack) > limit:
            return limit + 1
    return count


def _check_geometry(r: _Reader, robot: Robot) -> None:
    """Anchors distinct, and the structure matrix (2.10) of full rank n at home: else no wrench
    (2.39) can be balanced in every direction (e.g. every b_i = 0 leaves rank 3)."""
    for i in range(robot.m):
        for j in range(i):
            if np.allclose(robot.a[i], robot.a[j], atol=1e-9):
                raise r.error(f"geometry.a[{i}]", f"same anchor point as geometry.a[{j}]: {robot.a[i].tolist()}")
    AT = inverse_kinematics(robot, robot.home).AT
    rank = np.linalg.matrix_rank(AT, tol=1e-9 * np.abs(AT).max())
    if rank < robot.n:
        raise r.error("geometry.b", f"the structure matrix A^T (2.10) at home has rank {rank} < {robot.n}: "
                      "the cables cannot balance every wrench (are the platform points b_i all alike?)")


def _check_home(r: _Reader, robot: Robot) -> None:
    """The home pose inside the frame (the box the anchors a_i span) and in the wrench-feasible
    workspace (2.39)-(2.40): cable forces within [f_min, f_max] hold the platform's weight there.
    The program check, the simulator and the interpreter all start from home."""
    lo, hi = robot.a.min(axis=0), robot.a.max(axis=0)
    position = robot.home[:3]
    for i, axis in enumerate("xyz"):
        if not lo[i] < position[i] < hi[i]:
            raise r.error("home", f"position {position.tolist()} m is outside the frame: the anchors geometry.a "
                          f"span {axis} in ({lo[i]:g}, {hi[i]:g}) m")
    AT, w = static_problem(robot, robot.home)
    f_min, f_max = robot.cable.f_min, robot.cable.f_max
    if robot.m - robot.n <= 2:                   # the exact test of the workspace code
        held = wrench_feasible(AT, w, f_min, f_max)
    else:                                        # beyond its kernel dimension: the QP (3.27)-(3.28)
        held = quadratic_program(AT, w, f_min, f_max, backend="daqp").feasible
    if not held:
        raise r.error("home", f"{robot.home.tolist()} is outside the wrench-feasible workspace (2.39)-(2.40): "
                      f"no cable forces within [f_min, f_max] hold the platform ({robot.platform.mass:g} kg) there")


def _read_robot(r: _Reader) -> Robot:
    name = r.raw("name")
    if not isinstance(name, str) or not name:
        raise r.error("name", f"expected a non-empty string, got {_short(name)}")
    m = r.integer("m", minimum=1)
    n = r.integer("n", minimum=1)
    if n != 6:
        raise r.error("n", f"only spatial robots with 6 DOF are supported, got {n}")
    if m < n:
        raise r.error("m", f"needs at least n = {n} cables, got {m}")
    if m > MAX_CABLES:
        raise r.error("m", f"at most {MAX_CABLES} cables are supported, got {m}")
    ws_min = r.array("workspace_box.min", (3,))
    ws_max = r.array("workspace_box.max", (3,))
    if np.any(ws_min >= ws_max):
        raise r.error("workspace_box", "min must be below max on every axis")
    robot = Robot(
        name=name,
        file=r.file,
        m=m,
        n=n,
        frame_size=r.array("frame_size", (3,), "positive"),
        gravity=r.array("gravity", (3,)),
        home=r.array("home", (6,)),
        workspace_min=ws_min,
        workspace_max=ws_max,
        swivelling_pulleys=r.boolean("geometry.swivelling_pulleys"),
        a=r.array("geometry.a", (m, 3)),
        b=r.array("geometry.b", (m, 3)),
        pulley_orientation=r.array("geometry.pulley_orientation_deg", (m, 3), deg=True),
        r_p=r.array("geometry.r_p", (m,), "positive"),
        l_0=r.array("geometry.l_0", (m,), "nonnegative"),
        cable=_read_cable(r, m),
        drive=_read_drive(r),
        platform=PlatformParams(
            mass=r.scalar("platform.mass", "positive"),
            center_of_gravity=r.array("platform.center_of_gravity", (3,)),
            inertia=_read_inertia(r),
        ),
        sensor=SensorParams(
            range=r.scalar("sensor.range", "positive"),
            bits=r.integer("sensor.bits", minimum=1),
            noise_std=r.scalar("sensor.noise_std", "nonnegative"),
            gamma_1=r.scalar("sensor.gamma_1", "positive"),
            gamma_0=r.scalar("sensor.gamma_0"),
            beta_1=float(np.deg2rad(r.scalar("sensor.beta_1_deg", "nonnegative"))),
        ),
        friction=_read_friction(r, m),
        energy=_read_energy(r, m) if "energy" in r.data else None,
    )
    _check_geometry(r, robot)
    _check_home(r, robot)
    r.check_unknown()
    return robot


def _read_cable(r: _Reader, m: int) -> CableParams:
    cable = CableParams(
        diameter=r.scalar("cable.diameter", "positive"),
        k_spec_nominal=r.scalar("cable.k_spec_nominal", "positive"),
        k0=r.scalar("cable.k0", "positive"),
        k1=r.scalar("cable.k1", "nonnegative"),
        k2=r.scalar("cable.k2", "nonnegative"),
        f_min=r.array("cable.f_min", (m,), "nonnegative"),
        f_max=r.array("cable.f_max", (m,), "positive"),
    )
    if np.any(cable.f_min >= cable.f_max):
        raise r.error("cable.f_min", "must be below cable.f_max for every cable")
    return cable


def _read_drive(r: _Reader) -> DriveParams:
    drive = DriveParams(
        model=r.choice("drive.model", ("pt1_deadtime", "second_order")),
        T_1=r.scalar("drive.T_1", "nonnegative"),
        T_d=r.scalar("drive.T_d", "nonnegative"),
        T_w=r.scalar("drive.T_w", "nonnegative"),
        zeta=r.scalar("drive.zeta", "nonnegative"),
        v_max=r.scalar("drive.v_max", "positive"),
        drum_radius=r.scalar("drive.drum_radius", "positive"),
        gear_ratio=r.scalar("drive.gear_ratio", "positive"),
    )
    if drive.model == "second_order" and not (drive.T_w > 0.0 and drive.zeta > 0.0):
        raise r.error("drive.T_w", "second_order drives need T_w > 0 and zeta > 0")
    return drive


def _read_inertia(r: _Reader) -> np.ndarray:
    inertia = r.array("platform.inertia", (3, 3))
    if not np.allclose(inertia, inertia.T):
        raise r.error("platform.inertia", "must be symmetric")
    if np.min(np.linalg.eigvalsh(inertia)) <= 0.0:
        raise r.error("platform.inertia", "must be positive definite")
    return inertia


def _read_friction(r: _Reader, m: int) -> FrictionParams:
    n_p = r.array("friction.n_pulleys", (m,), "positive")
    if np.any(n_p != np.round(n_p)):
        raise r.error("friction.n_pulleys", f"expected whole numbers, got {n_p.tolist()}")
    n_p = n_p.astype(int)
    n_p.setflags(write=False)
    return FrictionParams(
        n_pulleys=n_p,
        beta_inner=float(np.deg2rad(r.scalar("friction.beta_inner_deg", "nonnegative"))),
        mu=r.array("friction.mu", (m,), "nonnegative"),
        sigma=r.array("friction.sigma", (m,), "positive"),
        F_pv=r.array("friction.F_pv", (m,), "nonnegative"),
    )


def _read_energy(r: _Reader, m: int) -> EnergyParams:
    efficiencies = ("c_m", "c_pm", "c_pg")
    values = {key: r.scalar(f"energy.{key}", "positive") for key in
              ("r_w", "J_w", "alphadot_s", "c_m", "R", "Psi_m", "c_pm")}
    values.update({key: r.scalar(f"energy.{key}", "nonnegative") for key in
                   ("mu_w", "F_wv", "F_s", "c_n1", "c_n2", "P_0", "c_pg")})
    for key in efficiencies:
        if values[key] > 1.0:
            raise r.error(f"energy.{key}", f"an efficiency must be <= 1, got {values[key]}")
    return EnergyParams(pulley_mu=r.array("energy.pulley_mu", (m,), "nonnegative"),
                        pulley_F_pv=r.array("energy.pulley_F_pv", (m,), "nonnegative"), **values)


# --- public API ------------------------------------------------------------------------------


def available_robots() -> list[str]:
    """Names of the robots shipped with the project (usable with :func:`load_robot`)."""
    return sorted(p.stem for p in ROBOTS_DIR.glob("*.yaml"))


def robot_path(name_or_path: str | Path) -> Path:
    """The YAML file of a shipped robot name (e.g. ``"ipanema3_mini"``) or a path to a file."""
    candidate = Path(name_or_path)
    if candidate.suffix in (".yaml", ".yml"):
        return candidate
    shipped = ROBOTS_DIR / f"{name_or_path}.yaml"
    if not shipped.exists() and candidate.exists():   # a file (or directory) of another name: say what it is
        return candidate
    if not shipped.exists():
        raise RobotFileError(
            f"unknown robot {str(name_or_path)!r}; shipped robots: {', '.join(available_robots())}"
        )
    return shipped


def load_robot(name_or_path: str | Path) -> Robot:
    """Load and validate a robot description; raises RobotFileError naming file and key."""
    path = robot_path(name_or_path)
    try:
        data = load_yaml(path, "robot file")     # duplicate keys, nesting and encoding refused in words
    except YamlFileError as exc:
        raise RobotFileError(str(exc)) from None
    if not isinstance(data, dict):
        raise RobotFileError(f"{path}: expected a mapping at the top level")
    if _count_values(data, MAX_VALUES) > MAX_VALUES:
        raise RobotFileError(f"{path}: expands to more than {MAX_VALUES} values (YAML aliases nested too deep?)")
    return _read_robot(_Reader(data, path))

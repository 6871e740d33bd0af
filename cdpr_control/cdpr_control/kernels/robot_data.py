"""The robot's constants as plain contiguous arrays and floats, the arguments of the kernels.

numba cannot take the :class:`cdpr_control.model.robot.Robot` dataclass; :func:`robot_data` flattens it
once per robot object (cached by identity, robots are immutable) into a :class:`RobotData`.

numba compiles one machine-code version per combination of argument types, and an array's type
includes its layout and whether it is read-only (the robot's arrays are). The wrappers hand every
array over as a writeable C-contiguous float64 array (:func:`vector`), so that one version serves
every caller and :func:`cdpr_control.kernels.warm_up` loads the only one that runs. Results come
back in arrays the wrapper allocates (an array returned by a compiled function costs about 1 us to
hand over to Python, an argument 0.2 us).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cdpr_control.model.kinematics import pulley_frames


class RobotData(NamedTuple):
    """Per-robot constants of the kernels (SI units, shapes for m cables)."""

    a: np.ndarray            # (m, 3) base vectors a_i
    b: np.ndarray            # (m, 3) platform vectors b_i
    R_A: np.ndarray          # (m, 3, 3) pulley frames K_A (2.3)
    r_p: np.ndarray          # (m,) pulley radius
    pulleys: bool            # swivelling pulleys (2.3)-(2.9) or fixed anchors (2.1)
    l_0: np.ndarray          # (m,) winch-to-pulley length (2.14)
    k0: float                # cable model (2.16)
    k1: float
    k2: float
    mass: float              # platform (2.33)
    cog: np.ndarray          # (3,) centre of gravity, platform frame
    inertia: np.ndarray      # (3, 3) about the centre of gravity, platform frame
    gravity: np.ndarray      # (3,) base frame


_F64 = np.dtype(float)


def vector(v) -> np.ndarray:
    """v as a writeable aligned C-contiguous float64 array (the type the kernels are compiled for):
    v itself when it is one already (the kernels do not write to their inputs), else a copy.

    ``flags.carray`` is those three flags in one attribute (numpy's NPY_ARRAY_CARRAY), a fifth
    cheaper than reading two; aligned as well, as numba types an unaligned array as another type."""
    if type(v) is np.ndarray and v.dtype is _F64 and v.flags.carray:
        return v
    return np.array(v, dtype=float, order="C")


_CACHE: dict[int, tuple] = {}
# one RobotData per distinct robot: each node of a composed graph loads its own robot object from the
# same file, and the period's results keyed on the RobotData (the IK of x_d, kernels._packed) then
# serve every node of the process
_BY_VALUE: dict[tuple, RobotData] = {}


def robot_data(robot) -> RobotData:
    """The :class:`RobotData` of ``robot``, built on first use and cached per robot object; robots
    of equal constants share one (the same object: ``robot_data(a) is robot_data(b)``)."""
    entry = _CACHE.get(id(robot))
    if entry is None or entry[0] is not robot:
        def arr(v):
            return np.ascontiguousarray(v, dtype=float).copy()      # writeable: one numba type
        c, p = robot.cable, robot.platform
        data = RobotData(arr(robot.a), arr(robot.b), arr(pulley_frames(robot)), arr(robot.r_p),
                         bool(robot.swivelling_pulleys), arr(robot.l_0), float(c.k0), float(c.k1),
                         float(c.k2), float(p.mass), arr(p.center_of_gravity), arr(p.inertia),
                         arr(robot.gravity))
        data = _BY_VALUE.setdefault(_value_key(data), data)
        entry = _CACHE[id(robot)] = (robot, data)
    return entry[1]


def _value_key(data: RobotData) -> tuple:
    """The exact values of every constant (bytes: -0.0 and 0.0 differ, as they may for a kernel)."""
    return tuple((v.shape, v.tobytes()) if isinstance(v, np.ndarray) else (type(v), v) for v in data)

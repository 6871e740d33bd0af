"""Optional contact geometry: planes (floor, wall), a cylinder (the oil barrel of thesis section
5.1.3) and the platform's own contact shape, as pybullet collision objects.

Contact is penalty-based with the obstacle's stiffness [N/m] and damping [N s/m] per contact point
and Coulomb friction mu (pybullet multiplies the friction coefficients of the two bodies; the
platform's is 1). The default platform shape is a sphere (a tool tip), which touches with one
contact point, so ``stiffness`` is the contact stiffness the platform feels; a box touching a
plane flat does so at four points, each with that stiffness.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class ContactMaterial:
    stiffness: float = 1e5      # N/m per contact point
    damping: float = 1e3        # N s/m per contact point
    friction: float = 0.5       # -, Coulomb coefficient

    def __post_init__(self):
        if not (self.stiffness > 0.0 and self.damping >= 0.0 and self.friction >= 0.0):
            raise ValueError(f"contact material needs stiffness > 0, damping >= 0, friction >= 0: {self}")


@dataclass(frozen=True)
class Plane:
    """Half space behind the plane through ``point`` with outward ``normal`` (a floor or a wall)."""

    point: tuple = (0.0, 0.0, 0.0)
    normal: tuple = (0.0, 0.0, 1.0)
    material: ContactMaterial = field(default_factory=ContactMaterial)

    @classmethod
    def floor(cls, height: float, material: ContactMaterial | None = None) -> "Plane":
        return cls((0.0, 0.0, height), (0.0, 0.0, 1.0), material or ContactMaterial())


@dataclass(frozen=True)
class Cylinder:
    """Solid cylinder of ``radius`` and ``length`` centred at ``center`` along ``axis`` (base frame)."""

    center: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (0.0, 0.0, 1.0)
    radius: float = 0.3
    length: float = 0.9
    material: ContactMaterial = field(default_factory=ContactMaterial)

    def __post_init__(self):
        if not (self.radius > 0.0 and self.length > 0.0):
            raise ValueError(f"cylinder needs radius > 0 and length > 0: {self}")


@dataclass(frozen=True)
class PlatformShape:
    """Contact shape of the platform in its own frame.

    kind "sphere": a tool tip of radius ``size`` [m] centred at ``offset``; kind "box": half
    extents ``size`` (3,) centred at ``offset``; size None spans the platform anchors b_i.
    """

    kind: str = "sphere"
    size: object = None
    offset: tuple | None = None

    def __post_init__(self):
        if self.kind not in ("sphere", "box"):
            raise ValueError(f"platform shape kind must be 'sphere' or 'box', got {self.kind!r}")


def _unit(v, what: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(v))
    if v.shape != (3,) or not n > 0.0:
        raise ValueError(f"{what} must be a non-zero 3-vector, got {v.tolist()}")
    return v / n


def _quat_z_to(axis) -> list:
    """pybullet quaternion (x, y, z, w) of a rotation taking e_z onto the unit vector ``axis``."""
    z = np.array([0.0, 0.0, 1.0])
    c = np.cross(z, axis)
    if np.linalg.norm(c) < 1e-12:
        return [0.0, 0.0, 0.0, 1.0] if axis[2] > 0 else [1.0, 0.0, 0.0, 0.0]
    angle = np.arccos(np.clip(axis[2], -1.0, 1.0))
    return list(Rotation.from_rotvec(c / np.linalg.norm(c) * angle).as_quat())


def add_obstacle(pb, client: int, obstacle) -> int:
    """Create a static pybullet body for a Plane or Cylinder; returns its body id."""
    if isinstance(obstacle, Plane):
        normal = _unit(obstacle.normal, "plane normal")
        shape = pb.createCollisionShape(pb.GEOM_PLANE, planeNormal=normal.tolist(), physicsClientId=client)
        body = pb.createMultiBody(0.0, shape, basePosition=list(map(float, obstacle.point)),
                                  physicsClientId=client)
    elif isinstance(obstacle, Cylinder):
        axis = _unit(obstacle.axis, "cylinder axis")
        shape = pb.createCollisionShape(pb.GEOM_CYLINDER, radius=obstacle.radius, height=obstacle.length,
                                        physicsClientId=client)
        body = pb.createMultiBody(0.0, shape, basePosition=list(map(float, obstacle.center)),
                                  baseOrientation=_quat_z_to(axis), physicsClientId=client)
    else:
        raise TypeError(f"unknown obstacle {obstacle!r}: use contacts.Plane or contacts.Cylinder")
    mat = obstacle.material
    pb.changeDynamics(body, -1, contactStiffness=mat.stiffness, contactDamping=mat.damping,
                      lateralFriction=mat.friction, restitution=0.0, physicsClientId=client)
    return body


def default_tool(b: np.ndarray) -> tuple[float, tuple]:
    """(radius, centre) of the default tool tip: a tenth of the anchors' extent, just below them."""
    lo, hi = b.min(axis=0), b.max(axis=0)
    radius = 0.1 * float(np.max(hi - lo))
    return radius, (float(0.5 * (lo[0] + hi[0])), float(0.5 * (lo[1] + hi[1])), float(lo[2]) - radius)


def platform_collision_shape(pb, client: int, shape: PlatformShape, b: np.ndarray) -> int:
    """pybullet collision shape of the platform (frame: the platform frame)."""
    lo, hi = b.min(axis=0), b.max(axis=0)
    if shape.kind == "sphere":
        radius, offset = default_tool(b)
        radius = float(shape.size) if shape.size is not None else radius
        offset = shape.offset if shape.offset is not None else offset
        if not radius > 0.0:
            raise ValueError(f"sphere radius must be > 0 m, got {radius}")
        return pb.createCollisionShape(pb.GEOM_SPHERE, radius=radius,
                                       collisionFramePosition=list(map(float, offset)), physicsClientId=client)
    half = np.asarray(shape.size, dtype=float) if shape.size is not None else np.maximum(0.5 * (hi - lo), 1e-3)
    offset = shape.offset if shape.offset is not None else 0.5 * (lo + hi)
    if half.shape != (3,) or np.any(half <= 0.0):
        raise ValueError(f"box half extents must be 3 positive numbers, got {half.tolist()}")
    return pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half.tolist(),
                                   collisionFramePosition=list(map(float, offset)), physicsClientId=client)

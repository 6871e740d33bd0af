"""Cable model, thesis section 2.1.2: free length (2.14), specific stiffness (2.15)-(2.16) and the
force <-> elongation relation (2.17)/(3.7) of the progressive (non-linear) cable.

All functions take per-cable arrays (..., m) and broadcast. Forces f [N], elongations dq [m] with
dq > 0 for a cable under tension, lengths [m]. The model is valid for 0 <= f < sqrt(k0 / k2)
(beyond, more force would mean less elongation); with k2 = 0 it is valid for every f >= 0.
"""

from __future__ import annotations

import numpy as np


def total_free_length(robot, q) -> np.ndarray:
    """l_t = q + l_0 (2.14): free cable length between drum and platform."""
    return np.asarray(q, dtype=float) + robot.l_0


def k_spec(f, k0, k1, k2):
    """k_spec = k0 + k1 f + k2 f^2 (2.16) [N] of forces f >= 0: the one numpy form of the law
    (its compiled twin: kernels.model.k_spec)."""
    return k0 + f * (k1 + k2 * f)


def specific_stiffness(robot, f) -> np.ndarray:
    """k_spec (2.16) [N] of the robot's cable; f <= 0 (slack) gives k0."""
    c = robot.cable
    return k_spec(np.maximum(np.asarray(f, dtype=float), 0.0), c.k0, c.k1, c.k2)


def stiffness(robot, f, l_t) -> np.ndarray:
    """Secant cable stiffness C = k_spec(f) / l_t (2.15) [N/m], the diagonal of K_l in (3.8)."""
    return specific_stiffness(robot, f) / l_t


def tangent_stiffness(robot, f, l_t) -> np.ndarray:
    """df/d(dq) of (2.17) at constant l_t [N/m]: the K_l of (2.20) used in K_c (2.22).

    Differentiating f l_t = k_spec(f) dq gives k_spec^2 / (l_t (k0 - k2 f^2)); equal to (2.15) for a
    linear cable (k1 = k2 = 0). A slack cable (f <= 0) has zero stiffness.
    """
    c = robot.cable
    f = np.asarray(f, dtype=float)
    fp = np.maximum(f, 0.0)
    k = k_spec(fp, c.k0, c.k1, c.k2)
    return np.where(f > 0.0, k * k / (l_t * (c.k0 - c.k2 * fp * fp)), 0.0)


def elongation_from_force(robot, f, l_t) -> np.ndarray:
    """dq = f l_t / k_spec(f) (3.7) for a cable of free length l_t.

    Negative forces (sensor noise on a slack cable) map linearly with k0, so the map stays monotone.
    """
    f = np.asarray(f, dtype=float)
    return f * l_t / specific_stiffness(robot, f)


def elongation_from_force_and_winch_length(robot, f, theta) -> np.ndarray:
    """dq of (3.7) when l_t is not known yet but the winch length theta is.

    With l_t = q + l_0 (2.14) and q = theta + dq (2.24), (3.7) reads
    dq = f (theta + dq + l_0) / k_spec, so dq = f (theta + l_0) / (k_spec - f). This is the exact
    inverse of force_from_elongation(dq, total_free_length(q)) at q = theta + dq.
    """
    f = np.asarray(f, dtype=float)
    return f * (np.asarray(theta, dtype=float) + robot.l_0) / (specific_stiffness(robot, f) - f)


def force_from_elongation(robot, dq, l_t) -> np.ndarray:
    """f solving f = k_spec(f) dq / l_t (2.17) for f; dq <= 0 (slack) gives f = 0.

    With the strain e = dq / l_t, k2 e f^2 + (k1 e - 1) f + k0 e = 0; the root continuous with
    f = k0 e at small strain is f = 2 k0 e / ((1 - k1 e) + sqrt((1 - k1 e)^2 - 4 k0 k2 e^2)).
    Beyond the model's range (elongation above that at f = sqrt(k0/k2)) the result is NaN.
    """
    c = robot.cable
    e = np.maximum(np.asarray(dq, dtype=float) / l_t, 0.0)
    s = 1.0 - c.k1 * e
    disc = s * s - 4.0 * c.k0 * c.k2 * e * e
    valid = (disc >= 0.0) & (s > 0.0)
    root = np.sqrt(np.where(valid, disc, 0.0))
    return np.where(valid, 2.0 * c.k0 * e / np.where(valid, s + root, 1.0), np.nan)

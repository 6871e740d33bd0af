"""Hand-made force distribution problems for the tests: point-anchor robots (the structure matrix
(2.10) built here, independently of the project's kinematics) at random positions."""
import numpy as np


def point_anchor_AT(a, b, r):
    """A^T (6, m) of (2.10) for fixed anchors a (m, 3), platform vectors b (m, 3), position r."""
    u = a - (r + b)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return np.vstack([u.T, np.cross(b, u).T])


def random_problems(n, m=8, seed=0, mass=(20.0, 300.0)):
    """A^T (n, 6, m) and weights w (n, 6) of random boxes-in-a-box robots and positions."""
    rng = np.random.default_rng(seed)
    AT, w = np.empty((n, 6, m)), np.empty((n, 6))
    for k in range(n):
        a = rng.uniform(-1, 1, (m, 3)) * [6.0, 4.0, 2.0]
        a[: m // 2, 2] = np.abs(a[: m // 2, 2]) + 2.0          # upper cables above the platform
        b = rng.uniform(-0.5, 0.5, (m, 3))
        AT[k] = point_anchor_AT(a, b, rng.uniform(-1.0, 1.0, 3))
        w[k] = np.r_[0.0, 0.0, -9.81 * rng.uniform(*mass), rng.normal(0.0, 20.0, 3)]
    return AT, w

"""The feasible set of (2.40) in kernel coordinates, Lambda = {lambda : f_min <= f_ext + H lambda <= f_max}.

For r = m - n <= 2 (every robot of this project has r = 2) Lambda is an interval or a polygon and
the questions the cable force algorithms ask have exact, loop-free answers over a whole batch:

* :func:`is_nonempty`: is the pose wrench feasible (2.39)-(2.40)? Fourier-Motzkin elimination of
  one coordinate leaves pairwise bounds on the other; 28 pairs for 8 cables.
* :func:`project`: the QP (3.27)-(3.28), by (*) of :mod:`.nullspace` the point of Lambda nearest
  to lambda_0 = H^T f_ref: lambda_0 itself, its projection onto an edge line, or a vertex; all
  candidates are enumerated and the nearest feasible one wins.
* :func:`puncture`: PM/CFE/IPM, the lowest-tension point of a line inside Lambda.

Arrays are batch-last as in :mod:`.nullspace`; tol widens the limits (force units, N).
"""
from __future__ import annotations

import itertools

import numpy as np

from cdpr_control.force_distribution.nullspace import Nullspace, nullspace
from cdpr_control.force_distribution.problem import as_batch


def check_rank(r: int) -> None:
    """The exact set operations need a kernel of dimension <= 2 (m <= n + 2 cables)."""
    if r > 2:
        raise ValueError(f"exact kernel methods support r = m - n <= 2, got r = {r}; "
                         "use a QP backend such as 'daqp'")


def _bounds(ns: Nullspace, f_min, f_max, tol):
    """Limits on H lambda: lo <= H lambda <= hi, (m, B)."""
    return f_min - ns.f_ext - tol, f_max - ns.f_ext + tol


def is_nonempty(ns: Nullspace, f_min, f_max, tol) -> np.ndarray:
    """(B,) True where a force distribution within [f_min - tol, f_max + tol] exists (2.40)."""
    r = ns.H.shape[0]
    check_rank(r)
    lo, hi = _bounds(ns, f_min, f_max, tol)
    if r == 0:
        return ns.ok & (lo <= 0.0).all(axis=0) & (hi >= 0.0).all(axis=0)
    if r == 1:
        lower, upper, const_ok = _interval(ns.H[0], lo, hi)
        return ns.ok & const_ok & (lower <= upper)
    return ns.ok & _polygon_nonempty(ns.H, lo, hi)


def _interval(g, lo, hi):
    """Bounds on t from lo <= g t <= hi per row (rows with g = 0 only need lo <= 0 <= hi)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = lo / g, hi / g
    pos, neg = g > 0.0, g < 0.0
    lower = np.where(pos, a, np.where(neg, b, -np.inf)).max(axis=0)
    upper = np.where(pos, b, np.where(neg, a, np.inf)).min(axis=0)
    const_ok = ((g != 0.0) | ((lo <= 0.0) & (hi >= 0.0))).all(axis=0)
    return lower, upper, const_ok


def _polygon_nonempty(H, lo, hi):
    """Fourier-Motzkin for r = 2, eliminating mu_2 in coordinates mu = R lambda.

    A cable with g_2,i != 0 gives mu_2 >= a_i + b_i mu_1 and mu_2 <= c_i + b_i mu_1 (same slope);
    the polygon is nonempty iff some mu_1 satisfies a_i + b_i mu_1 <= c_j + b_j mu_1 for all
    i != j and the bounds of the cables with g_2,i = 0, which constrain mu_1 alone. R is a fixed
    rotation by a generic angle, so that symmetric poses give no exact zeros.
    """
    g1 = _COS * H[0] + _SIN * H[1]
    g2 = _COS * H[1] - _SIN * H[0]
    steep = np.abs(g2) > 1e-12 * (np.abs(g1) + np.abs(g2))          # cable bounds mu_2
    lower1, upper1, const_ok = _interval(np.where(steep, 0.0, g1), np.where(steep, -1.0, lo),
                                         np.where(steep, 1.0, hi))  # cables bounding mu_1 only
    g2 = np.where(steep, g2, 1.0)
    up = g2 > 0.0
    a = np.where(steep, np.where(up, lo, hi) / g2, -np.inf)
    c = np.where(steep, np.where(up, hi, lo) / g2, np.inf)
    b = np.where(steep, -g1 / g2, 0.0)
    # per pair: L_i <= U_j and L_j <= U_i, i.e. k mu_1 <= c_j - a_i and k mu_1 >= a_j - c_i with
    # k = b_i - b_j; both bounds divide by the same k and a <= c orders them, so the pair allows
    # mu_1 in [min, max] of the two quotients (for either sign of k).
    I, J = _PAIRS.get(H.shape[1]) or _pairs(H.shape[1])
    k = b[I] - b[J]
    upper_rhs, lower_rhs = c[J] - a[I], a[J] - c[I]
    with np.errstate(divide="ignore", invalid="ignore"):
        q1, q2 = upper_rhs / k, lower_rhs / k
    lower = np.maximum(np.minimum(q1, q2).max(axis=0), lower1)
    upper = np.minimum(np.maximum(q1, q2).min(axis=0), upper1)
    parallel_ok = ((k != 0.0) | ((upper_rhs >= 0.0) & (lower_rhs <= 0.0))).all(axis=0)
    return const_ok & parallel_ok & (lower <= upper)


_COS, _SIN = np.cos(0.7853981), np.sin(0.7853981)     # generic (not exactly pi/4) rotation


_PAIRS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _pairs(m):
    """Pairs i < j of cables (index arrays), cached per m."""
    I, J = np.array(list(itertools.combinations(range(m), 2))).T
    _PAIRS[m] = (I, J)
    return I, J


def puncture(ns: Nullspace, p, d, f_min, f_max, tol):
    """The point of the line p + t d inside Lambda with the lowest total tension, and whether the
    line meets Lambda at all (PM/CFE/IPM).

    p, d (r, B). Returns (t, ok), both (B,): the end of the feasible segment towards lower sum(f)
    (where sum(f) is constant along the line, t = 1); where the line misses Lambda t is 1 and ok
    False. The point lies on the exact limits; tol only decides whether the line meets Lambda.
    """
    v0 = (ns.H * p[:, None, :]).sum(axis=0)                          # H p, (m, B)
    g = (ns.H * d[:, None, :]).sum(axis=0)                           # H d
    # cables the line does not move (e.g. those IPM keeps fixed) must not bound t by round-off
    g = np.where(np.abs(g) > 1e-12 * np.abs(g).max(axis=0), g, 0.0)
    lo, hi = _bounds(ns, f_min, f_max, 0.0)
    lower_e, upper_e, _ = _interval(g, lo - v0, hi - v0)
    lower, upper, const_ok = _interval(g, lo - tol - v0, hi + tol - v0)
    ok = ns.ok & const_ok & (lower <= upper)
    slope = g.sum(axis=0)                                            # d sum(f) / dt
    # on the exact limits if they leave an interval, else in the middle of the tolerated one
    exact = lower_e <= upper_e
    with np.errstate(invalid="ignore"):
        middle = 0.5 * (lower + upper)
        t = np.where(slope > 0.0, np.where(exact, lower_e, middle), np.where(exact, upper_e, middle))
    t = np.where(slope == 0.0, np.clip(1.0, lower, upper), t)
    ok &= np.isfinite(t)
    return np.where(ok, t, 1.0), ok


def project(ns: Nullspace, lam0, f_min, f_max, tol):
    """The QP (3.27)-(3.28) in kernel coordinates: the point of Lambda nearest to lam0 (r, B).

    Returns (lam, ok, active): lam (r, B) the projection where ok (Lambda nonempty), else lam0 (the
    closed form (2.42), a continuous fallback); active (B,) the number of limits the solution
    touches (0 interior, 1 edge, 2 vertex) - the exact solver's "iterations".
    """
    r, B = lam0.shape
    check_rank(r)
    if B > _CHUNK:                # the candidates take (K, m, B) memory: keep it in the cache
        parts = [project(Nullspace(ns.f_ext[:, s:s + _CHUNK], ns.H[:, :, s:s + _CHUNK], ns.ok[s:s + _CHUNK]),
                         lam0[:, s:s + _CHUNK], f_min[:, s:s + _CHUNK], f_max[:, s:s + _CHUNK], tol)
                 for s in range(0, B, _CHUNK)]
        return tuple(np.concatenate(a, axis=-1) for a in zip(*parts))
    lo, hi = _bounds(ns, f_min, f_max, 0.0)                         # candidates on the limits
    cand = [lam0[:, None, :]]
    n_active = [np.zeros(1, dtype=np.int64)]
    if r >= 1:
        cand.append(_edge_points(ns.H, lam0, lo, hi))
        n_active.append(np.ones(cand[-1].shape[1], dtype=np.int64))
    if r == 2:
        cand.append(_vertices(ns.H, lo, hi))
        n_active.append(np.full(cand[-1].shape[1], 2, dtype=np.int64))
    lam = np.concatenate(cand, axis=1)                               # (r, K, B)
    active = np.concatenate(n_active)
    Hl = np.einsum("rmb,rkb->kmb", ns.H, lam)                        # (K, m, B)
    with np.errstate(invalid="ignore"):
        inside = ((Hl >= lo - tol) & (Hl <= hi + tol)).all(axis=1)   # NaN candidates drop out
    dist = np.where(inside, ((lam - lam0[:, None, :]) ** 2).sum(axis=0), np.inf)
    best = np.argmin(dist, axis=0)
    ok = ns.ok & np.isfinite(dist.min(axis=0))
    cols = np.arange(lam0.shape[1])
    return np.where(ok, lam[:, best, cols], lam0), ok, np.where(ok, active[best], 0)


_CHUNK = 1024


def _edge_points(H, lam0, lo, hi):
    """Projections of lam0 onto the 2m lines H_i lambda = lo_i / hi_i, (r, 2m, B)."""
    hh = (H * H).sum(axis=0)                                         # (m, B)
    Hl0 = (H * lam0[:, None, :]).sum(axis=0)
    Hr = np.concatenate([H, H], axis=1)                              # (r, 2m, B)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        step = np.concatenate([(lo - Hl0) / hh, (hi - Hl0) / hh])    # (2m, B)
        return lam0[:, None, :] + step[None] * Hr


def _vertices(H, lo, hi):
    """Intersections of the constraint lines of every two cables (4 per pair), (2, 4P, B)."""
    m = H.shape[1]
    I, J = _PAIRS.get(m) or _pairs(m)
    h1i, h2i, h1j, h2j = H[0, I], H[1, I], H[0, J], H[1, J]          # (P, B)
    det = h1i * h2j - h2i * h1j
    verts = []
    for bi, bj in itertools.product((lo, hi), repeat=2):
        ui, uj = bi[I], bj[J]
        with np.errstate(divide="ignore", invalid="ignore"):
            verts.append(np.stack([(ui * h2j - uj * h2i) / det, (h1i * uj - h1j * ui) / det]))
    return np.concatenate(verts, axis=1)


def wrench_feasible(AT, w, f_min, f_max, chunk: int = 4096) -> np.ndarray:
    """Is there any f with A^T f = -w and f_min <= f <= f_max (2.39)-(2.40)? For a batch.

    A^T (..., n, m), w (..., n), limits scalars, (m,) or (..., m); returns bool (...). Exact (no
    particular algorithm's view), the membership test of the wrench-feasible workspace W_QP;
    singular or non-finite poses are infeasible. Needs r = m - n <= 2.
    """
    p = as_batch(AT, w, f_min, f_max)
    out = np.empty(p.AT.shape[0], dtype=bool)
    for s in range(0, p.AT.shape[0], chunk):
        ns = nullspace(p.AT[s:s + chunk], p.w[s:s + chunk], orthonormal=False)
        out[s:s + chunk] = is_nonempty(ns, p.f_min[:, s:s + chunk], p.f_max[:, s:s + chunk], p.tol)
    return out.reshape(p.shape) if p.shape else bool(out[0])

"""The general solution (2.41) f = f_ext + H lambda_H of the structure equation A^T f = -w.

For a batch of structure matrices A^T this gives the particular solution f_ext = -A^{+T} w and an
orthonormal kernel basis H (r = m - n columns). All cable force algorithms of section 2.2.2 then
work in the r coordinates lambda of the internal tension: H is orthonormal and f_ext is orthogonal
to it, so for every f = f_ext + H lambda

    |f - f_ref|^2 = |lambda - H^T f_ref|^2 + const ,                                   (*)

i.e. the closed form (2.42) is lambda_0 = H^T f_ref and the QP (3.27) is the Euclidean
projection of lambda_0 onto the polygon of lambdas whose forces satisfy (2.39).

Layout: arrays here are batch-last, f_ext (m, B), H (r, m, B), lambda (r, B), so that every
numpy operation runs over a contiguous batch (a LAPACK call per 6x8 matrix would cost more than
the arithmetic). The decomposition is Gram-Schmidt with re-orthogonalisation on the rows of A^T.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

# A row of A^T whose part orthogonal to the rows before it is shorter than this (relative to the
# longest row) makes A^T rank deficient: a singular pose.
RANK_RTOL = 1e-10
# Up to this many poses the SVD (one LAPACK call per pose) beats the column-wise batch code.
SMALL_BATCH = 16


class Nullspace(NamedTuple):
    """f = f_ext + H lambda solves A^T f = -w for every lambda (batch-last shapes)."""

    f_ext: np.ndarray   # (m, B) -A^{+T} w, (2.41)
    H: np.ndarray       # (r, m, B) orthonormal basis of the kernel of A^T, (2.41)
    ok: np.ndarray      # (B,) False where A^T is (numerically) rank deficient or not finite


def nullspace(AT, w, orthonormal: bool = True) -> Nullspace:
    """(2.41) for A^T (B, n, m) and w (B, n): f_ext and an orthonormal kernel basis H.

    With A^T = L Y (L lower triangular, Y orthonormal rows), A^{+T} = Y^T L^{-1}; the kernel is
    the complement of Y's rows, taken from the projector I - Y^T Y one column at a time, always
    the longest remaining one (pivoting), so H is well conditioned. Rank-deficient or non-finite
    poses give ok = False and zeros instead of NaN. orthonormal=False skips the
    re-orthogonalisation: f_ext and H then still solve (2.41), but (*) holds only to ~ eps cond(A^T)
    (enough for feasibility tests, which need no metric).
    """
    AT = np.asarray(AT, dtype=float)
    if AT.shape[0] <= SMALL_BATCH:
        return _nullspace_svd(AT, np.asarray(w, dtype=float))
    A = np.ascontiguousarray(np.moveaxis(AT, 0, -1))                              # (n, m, B)
    w = np.ascontiguousarray(np.asarray(w, dtype=float).T)                          # (n, B)
    n, m, B = A.shape
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        Y, L, ok = _gram_schmidt_rows(A, 2 if orthonormal else 1)
        z = np.empty((n, B))
        for j in range(n):                                   # L z = w by forward substitution
            z[j] = (w[j] - (L[j, :j] * z[:j]).sum(axis=0)) / L[j, j]
        f_ext = -(Y * z[:, None, :]).sum(axis=0)
        H = _kernel_basis(Y, m - n)
    ok &= np.isfinite(f_ext).all(axis=0) & np.isfinite(H).all(axis=(0, 1))
    f_ext[:, ~ok] = 0.0
    H[:, :, ~ok] = 0.0
    return Nullspace(f_ext, H, ok)


def _nullspace_svd(AT, w) -> Nullspace:
    """(2.41) by LAPACK's SVD A^T = U S V^T: cheaper than the column-wise code for a few poses."""
    B, n, m = AT.shape
    f_ext = np.zeros((m, B))
    H = np.zeros((m - n, m, B))
    ok = np.isfinite(AT).all(axis=(1, 2)) & np.isfinite(w).all(axis=1)
    if ok.any():
        U, S, Vt = np.linalg.svd(AT[ok])
        full_rank = S[:, -1] > RANK_RTOL * S[:, 0]
        ok[ok] = full_rank
        U, S, Vt = U[full_rank], S[full_rank], Vt[full_rank]
        z = np.einsum("bji,bj->bi", U, w[ok]) / S                          # S^-1 U^T w
        f_ext[:, ok] = -np.einsum("bim,bi->mb", Vt[:, :n], z)
        H[:, :, ok] = np.moveaxis(Vt[:, n:], 0, -1)
    return Nullspace(f_ext, H, ok)


def _gram_schmidt_rows(A, passes):
    """A^T = L Y for A^T stored (n, m, B): Y (n, m, B) orthonormal rows, L (n, n, B) lower."""
    n, m, B = A.shape
    Y = np.empty_like(A)
    L = np.zeros((n, n, B))
    scale = np.sqrt((A * A).sum(axis=1).max(axis=0))
    ok = np.isfinite(scale) & (scale > 0.0)
    for j in range(n):
        y = A[j].copy()
        for _ in range(passes):                              # twice is enough (Kahan/Parlett)
            c = np.einsum("jmb,mb->jb", Y[:j], y)
            y -= np.einsum("jb,jmb->mb", c, Y[:j])
            L[j, :j] += c
        norm = np.sqrt(np.einsum("mb,mb->b", y, y))
        ok &= norm > RANK_RTOL * scale
        L[j, j] = norm
        Y[j] = y / norm
    return Y, L, ok


def _kernel_basis(Y, r):
    """r orthonormal columns of I - Y^T Y (batch-last, (r, m, B)), longest column first."""
    n, m, B = Y.shape
    diag = 1.0 - np.einsum("jmb,jmb->mb", Y, Y)             # (m, B) squared column lengths
    H = np.empty((r, m, B))
    for k in range(r):
        e = (np.argmax(diag, axis=0) == np.arange(m)[:, None]).astype(float)   # one-hot e_i
        col = e - np.einsum("jmb,jb->mb", Y, np.einsum("jmb,mb->jb", Y, e))   # (I - Y^T Y) e_i
        for h in H[:k]:                                      # minus the columns taken before
            col -= h * np.einsum("mb,mb->b", h, e)
        H[k] = col / np.sqrt(np.einsum("mb,mb->b", col, e))
        diag -= H[k] * H[k]
    return H


def forces(ns: Nullspace, lam) -> np.ndarray:
    """f = f_ext + H lambda (2.41) for lambda (r, B) -> (m, B)."""
    return ns.f_ext + (ns.H * lam[:, None, :]).sum(axis=0)


def reference_coordinates(ns: Nullspace, f_ref) -> np.ndarray:
    """lambda_0 = H^T f_ref (r, B): the closed form (2.42) in kernel coordinates, by (*)."""
    return (ns.H * f_ref[None]).sum(axis=1)


def project_onto_fixed(ns: Nullspace, lam0, rows, bounds) -> np.ndarray:
    """The lambda closest to lam0 (r, B) with the forces of some cables fixed at given values.

    rows (k, B) cable indices, bounds (k, B) forces [N], k <= r. This is the closed form (2.42) of
    the system reduced by the fixed cables (the rank reduction of ACF): by (*) the reduced 2-norm
    problem is the projection onto the affine set {H_S^T lambda = bounds - f_ext_S}.
    """
    k, B = rows.shape
    cols = np.arange(B)
    C = ns.H[:, rows, cols]                                  # (r, k, B) kernel rows of fixed cables
    d = bounds - ns.f_ext[rows, cols] - (C * lam0[:, None, :]).sum(axis=0)
    G = (C[:, :, None, :] * C[:, None, :, :]).sum(axis=0)   # (k, k, B)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        if k == 1:
            y = d / G[0]
        elif k == 2:
            det = G[0, 0] * G[1, 1] - G[0, 1] * G[1, 0]
            y = np.stack([G[1, 1] * d[0] - G[0, 1] * d[1], G[0, 0] * d[1] - G[1, 0] * d[0]]) / det
        else:
            Gi = np.linalg.pinv(np.moveaxis(G, -1, 0))       # (B, k, k), only for r > 2
            y = np.einsum("bkj,jb->kb", Gi, d)
        return lam0 + (C * y[None]).sum(axis=1)

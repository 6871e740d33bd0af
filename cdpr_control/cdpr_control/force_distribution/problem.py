"""Inputs of a force distribution (2.40): shapes, the default reference force and the batch layout.

Every algorithm takes A^T (n, m) or a batch (..., n, m), the wrench w (n,) / (..., n) and the
per-cable limits f_min, f_max and reference force f_ref, each a scalar, (m,) or (..., m).
f_ref defaults to (f_min + f_max) / 2, the medium tension level of the closed form (2.42).
"""
from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from cdpr_control.force_distribution.result import DistributionResult, finish, limit_tolerance


class Batch(NamedTuple):
    """One distribution problem flattened to B poses; forces are batch-last (m, B)."""

    AT: np.ndarray        # (B, n, m)
    w: np.ndarray         # (B, n)
    f_min: np.ndarray     # (m, B)
    f_max: np.ndarray     # (m, B)
    f_ref: np.ndarray     # (m, B)
    shape: tuple          # leading dimensions of the caller's A^T, () for one pose
    tol: float            # limit tolerance [N], see result.limit_tolerance
    t0: float             # perf_counter at the start of the call

    @property
    def r(self) -> int:
        """Degree of redundancy r = m - n."""
        return self.AT.shape[2] - self.AT.shape[1]

    def result(self, method: str, f, ok, iterations) -> DistributionResult:
        """Package batch-last forces f (m, B) in the caller's shapes, see result.finish."""
        m = self.AT.shape[2]
        out = lambda a: np.moveaxis(a, 0, -1).reshape(self.shape + (m,))     # noqa: E731
        AT = self.AT.reshape(self.shape + self.AT.shape[1:])
        w = self.w.reshape(self.shape + self.w.shape[1:])
        ok = np.asarray(ok).reshape(self.shape)
        its = np.asarray(iterations).reshape(self.shape) if np.ndim(iterations) else iterations
        if not self.shape:
            ok, its = bool(ok), int(its)
        return finish(method, AT, w, out(f), ok, out(self.f_min), out(self.f_max), out(self.f_ref),
                      its, self.t0, tol=self.tol)


def as_batch(AT, w, f_min, f_max, f_ref=None) -> Batch:
    """Check shapes and flatten to B poses; f_ref None means (f_min + f_max) / 2."""
    t0 = time.perf_counter()
    AT = np.asarray(AT, dtype=float)
    w = np.asarray(w, dtype=float)
    if AT.ndim < 2 or w.shape != AT.shape[:-1]:
        raise ValueError(f"need A^T (..., n, m) and w (..., n), got {AT.shape} and {w.shape}")
    *shape, n, m = AT.shape
    if m < n:
        raise ValueError(f"need at least n = {n} cables, A^T has m = {m}")
    shape = tuple(shape)
    B = int(np.prod(shape, dtype=np.int64))
    f_min = np.asarray(f_min, dtype=float)
    f_max = np.asarray(f_max, dtype=float)
    f_ref = (f_min + f_max) / 2.0 if f_ref is None else np.asarray(f_ref, dtype=float)
    if np.any(f_min > f_max):
        raise ValueError("need f_min <= f_max for every cable")
    limits = [np.ascontiguousarray(np.broadcast_to(v, shape + (m,)).reshape(B, m).T)
              for v in (f_min, f_max, f_ref)]
    return Batch(AT.reshape(B, n, m), w.reshape(B, n), *limits, shape,
                 limit_tolerance(f_min, f_max), t0)

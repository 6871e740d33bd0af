"""The closed-form family of section 2.2.2: CF (2.42), CFE (2.45), PM, ACF and IPM.

All five work on a batch in the kernel coordinates of :mod:`.nullspace` (f = f_ext + H lambda),
where each is a few lines of geometry:

* CF: lambda_0 = H^T f_ref, the 2-norm closest solution to f_ref (2.42)/(2.43).
* PM: the line from f_ext (lambda = 0) through f_CF (lambda_0); the solution is its puncture
  through the limits, the point of the line inside them with the lowest total tension (Mueller,
  Reichert et al. 2014). For a uniform f_ref sum(f) rises along the line towards f_CF.
* CFE: f_ref is lowered towards f_min, f_ref,e = f_min + t (f_ref - f_min), until a cable reaches
  its limit (2.45); by (2.44) f_CFE moves on the line from f_CF(f_min) to f_CF. With equal limits
  for all cables this is the line of PM, hence CFE = PM as the thesis states.
* ACF: CF, then rank reduction: the cable with the largest violation is fixed at that limit and
  the closed form of the reduced system is evaluated, at most r times (Pott 2014a). Fixing
  cables is a projection onto an affine set in lambda (:func:`.nullspace.project_onto_fixed`).
* IPM: the puncture applied to ACF's result within ACF's reduced system (never more tension
  than ACF).

PM, CFE and IPM search the whole line, so they may also raise the tension where the closed form
leaves a cable below f_min; they are feasible wherever CF is. Infeasible poses return the
method's own continuous fallback (CF: its solution; PM/CFE: f_CF; ACF/IPM: the last reduction)
with status INFEASIBLE.
"""
from __future__ import annotations

import numpy as np

from cdpr_control.force_distribution.feasible_set import puncture as puncture_on_line
from cdpr_control.force_distribution.nullspace import (forces, nullspace, project_onto_fixed,
    reference_coordinates)
from cdpr_control.force_distribution.problem import as_batch
from cdpr_control.force_distribution.result import DistributionResult


def closed_form(AT, w, f_min, f_max, f_ref=None) -> DistributionResult:
    """CF (2.42): f = f_ref - A^{+T}(w + A^T f_ref); f_ref defaults to (f_min + f_max)/2."""
    p = as_batch(AT, w, f_min, f_max, f_ref)
    ns = nullspace(p.AT, p.w)
    f = forces(ns, reference_coordinates(ns, p.f_ref))
    return p.result("cf", f, ns.ok, 1)


def puncture(AT, w, f_min, f_max, f_ref=None) -> DistributionResult:
    """PM: the puncture of the line f_ext -> f_CF through the limits (lowest tension on it)."""
    p = as_batch(AT, w, f_min, f_max, f_ref)
    ns = nullspace(p.AT, p.w)
    lam0 = reference_coordinates(ns, p.f_ref)
    lam, ok = _puncture(ns, p, np.zeros_like(lam0), lam0)
    return p.result("pm", forces(ns, lam), ok, 1)


def closed_form_energy_efficient(AT, w, f_min, f_max, f_ref=None) -> DistributionResult:
    """CFE (2.45): f_CF evaluated for f_ref,e = f_min + t (f_ref - f_min), t as low as feasible."""
    p = as_batch(AT, w, f_min, f_max, f_ref)
    ns = nullspace(p.AT, p.w)
    lam0 = reference_coordinates(ns, p.f_ref)
    lam_min = reference_coordinates(ns, p.f_min)
    lam, ok = _puncture(ns, p, lam_min, lam0)
    return p.result("cfe", forces(ns, lam), ok, 1)


def advanced_closed_form(AT, w, f_min, f_max, f_ref=None) -> DistributionResult:
    """ACF: CF with rank reduction at the largest limit violation, at most r times (Pott 2014a)."""
    p = as_batch(AT, w, f_min, f_max, f_ref)
    ns = nullspace(p.AT, p.w)
    lam, _, _, n_fixed = _advanced(ns, p)
    return p.result("acf", forces(ns, lam), ns.ok, 1 + n_fixed)


def improved_puncture(AT, w, f_min, f_max, f_ref=None) -> DistributionResult:
    """IPM: ACF, then the puncture of the line f_ext' -> f_ACF of ACF's reduced system.

    f_ext' is the minimum-norm solution with the fixed cables at their limits, by (*) of
    :mod:`.nullspace` the projection of lambda = 0 onto the same affine set. A fully reduced
    (square) system leaves no freedom and IPM = ACF.
    """
    p = as_batch(AT, w, f_min, f_max, f_ref)
    ns = nullspace(p.AT, p.w)
    lam_acf, rows, bounds, n_fixed = _advanced(ns, p)
    lam = lam_acf.copy()
    for k in range(p.r):
        group = n_fixed == k
        if not group.any():
            continue
        start = np.zeros_like(lam_acf) if k == 0 else project_onto_fixed(
            ns, np.zeros_like(lam_acf), rows[:k], bounds[:k])
        lam_k, ok_k = _puncture(ns, p, start, lam_acf)
        lam = np.where(group & ok_k, lam_k, lam)
    return p.result("ipm", forces(ns, lam), ns.ok, 1 + n_fixed)


def _puncture(ns, p, start, end):
    """lambda on the line start + t (end - start) at its puncture (lowest tension inside the
    limits), and ok. Where the line misses the limits the result is its end point (f_CF / f_ACF).
    """
    d = end - start
    t, ok = puncture_on_line(ns, start, d, p.f_min, p.f_max, p.tol)
    return np.where(ok, start + t * d, end), ok


def _advanced(ns, p):
    """ACF's iteration: (lambda, fixed cables (k, B), their forces (k, B), number fixed (B,))."""
    B = p.AT.shape[0]
    cols = np.arange(B)
    lam0 = reference_coordinates(ns, p.f_ref)
    lam = lam0
    rows = np.zeros((0, B), dtype=np.int64)
    bounds = np.zeros((0, B))
    running = ns.ok.copy()
    n_fixed = np.zeros(B, dtype=np.int64)
    for _ in range(p.r):
        f = forces(ns, lam)
        below, above = p.f_min - f, f - p.f_max
        worst = np.argmax(np.maximum(below, above), axis=0)
        b, a = below[worst, cols], above[worst, cols]
        running &= np.maximum(b, a) > p.tol
        if not running.any():
            break
        limit = np.where(b > a, p.f_min[worst, cols], p.f_max[worst, cols])
        rows = np.vstack([rows, worst])
        bounds = np.vstack([bounds, limit])
        lam = np.where(running, project_onto_fixed(ns, lam0, rows, bounds), lam)
        n_fixed += running
    return lam, rows, bounds, n_fixed

"""Cable force algorithms by name: one entry point for all of section 2.2.2 and (3.27).

    distribute(AT, w, f_min, f_max, f_ref=None, method="qp", backend="kernel")

method is one of METHODS: "cf" (2.42), "cfe" (2.45), "pm", "acf", "ipm", "qp" (3.27)-(3.28);
backend only matters for "qp" (see :mod:`.qp`).
"""
from __future__ import annotations

from cdpr_control.force_distribution.closed_form import (advanced_closed_form, closed_form,
    closed_form_energy_efficient, improved_puncture, puncture)
from cdpr_control.force_distribution.qp import quadratic_program
from cdpr_control.force_distribution.result import DistributionResult

METHODS = {
    "cf": closed_form,
    "cfe": closed_form_energy_efficient,
    "pm": puncture,
    "acf": advanced_closed_form,
    "ipm": improved_puncture,
    "qp": quadratic_program,
}


def distribute(AT, w, f_min, f_max, f_ref=None, method: str = "qp",
               backend: str = "kernel") -> DistributionResult:
    """Cable forces f with A^T f = -w and f_min <= f <= f_max (2.40) by the named method.

    A^T (n, m) or (..., n, m), w (n,) or (..., n); f_min, f_max, f_ref scalars, (m,) or (..., m);
    f_ref None means (f_min + f_max)/2. Returns a :class:`DistributionResult` in the same leading
    shape; infeasible poses are flagged, never returned as solutions, and f is never NaN.
    """
    try:
        algorithm = METHODS[method]
    except KeyError:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}") from None
    if method == "qp":
        return algorithm(AT, w, f_min, f_max, f_ref, backend=backend)
    return algorithm(AT, w, f_min, f_max, f_ref)

"""Cable force distribution (thesis sections 2.2.2 and 3.6.2).

Algorithms (all take A^T, w, f_min, f_max, f_ref and return a DistributionResult):
    distribute(AT, w, f_min, f_max, f_ref=None, method="qp", backend="kernel")
    closed_form (CF), closed_form_energy_efficient (CFE), puncture (PM),
    advanced_closed_form (ACF), improved_puncture (IPM), quadratic_program (QP)
For a controller at 1 kHz: ForceDistributor (warm start, workspace border behaviour).
Workspace test: wrench_feasible(AT, w, f_min, f_max).
"""
from cdpr_control.force_distribution.border import BorderPolicy, ForceDistributor
from cdpr_control.force_distribution.closed_form import (advanced_closed_form, closed_form,
    closed_form_energy_efficient, improved_puncture, puncture)
from cdpr_control.force_distribution.feasible_set import wrench_feasible
from cdpr_control.force_distribution.methods import METHODS, distribute
from cdpr_control.force_distribution.qp import BACKENDS, QPSolver, quadratic_program
from cdpr_control.force_distribution.result import DistributionResult, Status

__all__ = [
    "BACKENDS", "METHODS", "BorderPolicy", "DistributionResult", "ForceDistributor", "QPSolver",
    "Status", "advanced_closed_form", "closed_form", "closed_form_energy_efficient", "distribute",
    "improved_puncture", "puncture", "quadratic_program", "wrench_feasible",
]

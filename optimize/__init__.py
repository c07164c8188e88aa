"""Minimum-friction designs of micro linear ball bearings.

* :mod:`optimize.problem` - :class:`DesignBounds`, :class:`Constraints`, :class:`DesignProblem`
* :mod:`optimize.dgp` - the problem as a disciplined geometric program in cvxpy
* :mod:`optimize.solve` - :func:`optimize_design`: enumeration of ball counts, a
  global optimum with a certificate, :class:`InfeasibleDesignError`
* :mod:`optimize.general` - :func:`optimize_model`: a local method for any μ model
* :mod:`optimize.pareto` - :func:`pareto_front`: μ against load or contact pressure
* :mod:`optimize.robust` - :func:`optimize_robust`: the worst case over an operating :class:`Envelope`
  (speed and condition ranges, angle tolerance), with its :class:`~optimize.proof.Proof` and the price of
  robustness; one module per method (:mod:`optimize.robust_gp`, :mod:`optimize.robust_vertex`,
  :mod:`optimize.robust_outer`, :mod:`optimize.certificates`) over :mod:`optimize.over_envelope`
* :mod:`optimize.envelope_bound`, :mod:`optimize.interval_bound`, :mod:`optimize.design_bound` - certified
  bounds of a calibrated model's μ and ``mu_upper`` over boxes of the envelope and of the designs
"""

from .general import optimize_model, physics_model
from .pareto import PARETO_OBJECTIVES, ParetoFront, pareto_front
from .problem import Constraints, ConstraintStatus, DesignBounds, DesignProblem, constraint_report
from .robust import Envelope, RobustResult, optimize_robust
from .solve import BallCountResult, InfeasibleDesignError, OptimizationResult, optimize_design

__all__ = [
    "DesignBounds",
    "Constraints",
    "DesignProblem",
    "ConstraintStatus",
    "constraint_report",
    "optimize_design",
    "OptimizationResult",
    "BallCountResult",
    "InfeasibleDesignError",
    "optimize_model",
    "physics_model",
    "pareto_front",
    "ParetoFront",
    "PARETO_OBJECTIVES",
    "Envelope",
    "RobustResult",
    "optimize_robust",
]

"""Friction of micro linear ball bearings: the model of Olaru et al. (COMEC 2005).

Pure, vectorized functions, one per equation, grouped by sub-domain:

* :mod:`physics.contact` - moduli, contact load, JKR radius and pressure (eqs 3, 4, 7, 8)
* :mod:`physics.surface` - adhesion and capillary forces (eqs 1, 2, 5, 6)
* :mod:`physics.lubrication` - Houpert's rolling force and the pressure force (eqs 9-13)
* :mod:`physics.moments` - hysteresis, pivoting and ball-ball moments (eqs 15-17)
* :mod:`physics.balance` - the ball's balance and μ (eqs 18-23), and the traction of a shear
  stress over the contact (eq 14)
* :mod:`physics.kernel` - every output at a point, composed of the functions above: the one kernel
  (its elementary functions: :mod:`physics.elementary`)
* :mod:`physics.bearing` - :func:`evaluate` (arrays, block by block, threads of an executor the
  caller passes in) and :func:`evaluate_point` (one point as Python floats)
* :mod:`physics.execution` - :class:`ExecutionOptions`: the kernel (numpy or numba) and the threads
* :mod:`physics.fused` and :mod:`physics.compiled` - the kernel traced into stages and compiled by
  numba (optional extra ``fast``); :mod:`physics.vectormath` - glibc's 4-wide tan, cbrt, log and
  exp for it

:data:`PARAMETERS` declares every input once (name, unit, default, range);
:data:`OUTPUTS` every output. Everything is SI except the groove angle in degrees.
"""

from .bearing import OUTPUTS, FrictionResult, evaluate, evaluate_point
from .execution import ExecutionOptions
from .materials import MATERIALS, Material, material_parameters
from .parameters import (
    CONVENTIONS,
    DEFAULT_CONVENTION,
    PARAMETERS,
    Parameter,
    defaults,
    unit_suffix,
    validate,
    validate_all,
)

__all__ = [
    "evaluate",
    "evaluate_point",
    "ExecutionOptions",
    "FrictionResult",
    "OUTPUTS",
    "PARAMETERS",
    "Parameter",
    "CONVENTIONS",
    "DEFAULT_CONVENTION",
    "MATERIALS",
    "Material",
    "material_parameters",
    "defaults",
    "unit_suffix",
    "validate",
    "validate_all",
]

"""The elementary functions of the equations, one spelling for a point and an array.

The equation functions (:mod:`physics.contact`, :mod:`physics.kernel`, ...) call these instead of
numpy's ufuncs, so that the same function text runs on Python floats (one point, without numpy's
per-call overhead and without turning the point's arithmetic into ``numpy.float64`` arithmetic) and
on anything else through numpy's ufuncs: arrays, and the traced values from which
:mod:`physics.fused` generates the numba kernel. On a Python float each returns a Python float with
the bits of numpy's ufunc on that value (sqrt by :func:`math.sqrt`: both are correctly rounded,
IEEE 754), so a point computes exactly what it computes inside an array.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["cbrt", "exp", "log", "sqrt", "tan"]


def sqrt(x):
    """Square root [x's unit^(1/2)]: :func:`math.sqrt` on a float (nan below 0, as numpy), else numpy's."""
    if isinstance(x, float):
        return math.sqrt(x) if x >= 0.0 else math.nan
    return np.sqrt(x)


def cbrt(x):
    """Cube root [x's unit^(1/3)]: ``numpy.cbrt``, a Python float for a float."""
    return float(np.cbrt(x)) if isinstance(x, float) else np.cbrt(x)


def tan(x):
    """Tangent of an angle in radians [1]: ``numpy.tan``, a Python float for a float."""
    return float(np.tan(x)) if isinstance(x, float) else np.tan(x)


def log(x):
    """Natural logarithm [1]: ``numpy.log``; log 0 = -inf (without numpy's warning for a float)."""
    if isinstance(x, float):
        return float(np.log(x)) if x else -math.inf
    return np.log(x)


def exp(x):
    """Exponential [1]: ``numpy.exp``, a Python float for a float."""
    return float(np.exp(x)) if isinstance(x, float) else np.exp(x)

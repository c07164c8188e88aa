"""A Gaussian-process surrogate as a :class:`physics.model.Model`: μ with its 95 % interval and trained space.

:class:`SurrogateModel` wraps a fitted :class:`surrogate.GaussianProcessSurrogate` in the interface
every layer uses: the service answers it for ``"surrogate:<id>"``, the optimizer takes it directly.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from microbearing.physics.model import Evaluation, Model, physics_inputs

__all__ = ["SurrogateModel"]


class SurrogateModel(Model):
    """A stored Gaussian-process surrogate of μ with its 95 % interval and trained space.

    Parameters
    ----------
    reference : str
        ``"surrogate:<id>"``.
    estimator : surrogate.GaussianProcessSurrogate
        The fitted surrogate.
    """

    kind = "surrogate"
    outputs = ("mu", "mu_lower", "mu_upper")
    has_interval = True
    # The Gaussian process's mean carries the rounding of its linear solve (~1e-11 relative), and its
    # standard deviation, which sets mu_lower and mu_upper, that of k(x, x) - v'v, a difference of
    # nearly equal numbers: ~1e-6 relative, and not the same for a point alone as among others in one
    # call. Finite differences amplify that to ~1e-4 of the bounds' derivatives; the surrogate's own
    # error (~1e-3 of mu) is far larger.
    derivative_rtol = 1e-3

    def __init__(self, reference: str, estimator: Any):
        space = estimator.space
        self.reference = reference
        self.estimator = estimator
        self.convention = space.convention
        self.fixed, self.fitted, self.required_columns = dict(space.fixed), {}, []
        domains = {name: (float(lo), float(hi)) for name, lo, hi in zip(space.names, space.lower, space.upper,
                                                                          strict=True)}
        self.inputs = physics_inputs(self.fixed, domains, required=space.names)

    def unread_words(self, name: str, value: float) -> str | None:
        # an input that is no dimension is not read: its answer would be the trained value's
        return None if name in self.estimator.space.names else self.estimator.space.unread_words(name, value)

    def evaluate(self, points: Mapping[str, Any], outputs: Sequence[str], *, pointer: str = "",
                 first_index: int = 0) -> Evaluation:
        # A prediction is finite wherever its inputs are valid: no problem to point at.
        prediction = self.estimator.predict_points(self.check(points))
        return Evaluation({name: getattr(prediction, name) for name in outputs}, prediction.outside_space)

    def __call__(self, points: Mapping[str, Any]) -> np.ndarray:
        return self.estimator.mu_model(points)

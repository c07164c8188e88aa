"""Gaussian-process surrogates of the friction model, trained on physics sweeps.

* :class:`Space` (:mod:`surrogate.space`): bounded physics parameters, scales, features;
* :func:`unit_design`, :func:`design`, :func:`fit_adaptive` (:mod:`surrogate.sampling`): designs
  of experiments and variance-driven adaptive sampling; :mod:`surrogate.designs`: grid axes and
  samples over ranges of inputs (the service's sweeps);
* :class:`GaussianProcessSurrogate` (:mod:`surrogate.model`): the estimator;
* :func:`accuracy`, :func:`holdout_metrics` (:mod:`surrogate.metrics`): held-out figures;
* :func:`dumps`, :func:`loads` (:mod:`surrogate.persist`): storage as JSON, no pickle;
* :func:`sobol_indices` (:mod:`surrogate.sensitivity`): Sobol' indices on a surrogate.
"""

from .metrics import accuracy, holdout_metrics
from .model import GaussianProcessSurrogate, Hyperparameters, SurrogatePrediction
from .persist import dumps, from_dict, loads, to_dict
from .sampling import AdaptiveFit, SamplingPlan, design, fit_adaptive, select_batch, unit_design
from .sensitivity import SobolIndices, sobol_indices
from .space import Space

__all__ = [
    "Space",
    "GaussianProcessSurrogate",
    "Hyperparameters",
    "SurrogatePrediction",
    "unit_design",
    "design",
    "select_batch",
    "fit_adaptive",
    "SamplingPlan",
    "AdaptiveFit",
    "accuracy",
    "holdout_metrics",
    "to_dict",
    "from_dict",
    "dumps",
    "loads",
    "SobolIndices",
    "sobol_indices",
]

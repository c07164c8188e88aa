"""A nested cross-validation whose first two outer folds add no term, shared by the tests that force the GP's
first test (tests/test_calibrate_honest.py, tests/test_calibrate_search_groups.py)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable


def two_folds_miss_the_term(real: Callable) -> Callable:
    """``real`` (``calibrate.report.nested_cross_validate``) with outer folds 0 and 1 predicted by the
    declared model, as when the selection in those folds adds nothing: their rows keep the residual a GP
    then takes up."""

    def nested_cross_validate(dataset, fit_parameters, baseline, *args, **kwargs):
        nested = real(dataset, fit_parameters, baseline, *args, **kwargs)
        fold_mu, oof = list(nested.fold_mu), nested.oof_mu.copy()
        for k in (0, 1):
            fold_mu[k] = baseline.fold_mu[k]
            oof[baseline.folds[k]] = baseline.fold_mu[k][baseline.folds[k]]
        return dataclasses.replace(nested, fold_mu=fold_mu, oof_mu=oof,
                                   fold_terms=[(), (), *nested.fold_terms[2:]])

    return nested_cross_validate

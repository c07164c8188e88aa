"""What each stage of a calibration (:func:`calibrate.report.calibrate`) hands to the next, and its options.

A calibration runs four stages, each a function of the ones before, and writes its report from them:

1. :class:`DataStage`: the checked data and the declared model fitted and cross-validated on them (the
   **before** figures);
2. :class:`CandidatesStage`: forward selection over the candidate terms (:mod:`calibrate.select`);
3. :class:`SelectionStage`: the selection judged held out (nested cross-validation, the **after**
   figure), a Gaussian-process baseline, and the chosen terms fitted on all rows;
4. :class:`UncertaintyStage`: outliers, groups, the scatter model, a GP on what the terms leave, the
   calibrated model with its intervals and domain, and its rivals;

then the report (:func:`calibrate.report.format_report`) in numbers and words.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from microbearing import physics

from .data import Dataset
from .domain import DataCloud
from .fit import FitResult
from .groups import GroupEffect
from .measurement import MeasurementSystem, with_censor_scale
from .model import CalibratedModel
from .rivals import Rival
from .scatter import ScatterModel
from .select import (
    FAMILY_ALPHA,
    MAX_SEARCH_ROWS,
    MAX_TERMS,
    SCATTER_ROUNDS,
    ModelCV,
    NestedValidation,
    SearchOptions,
    Selection,
)

__all__ = ["CalibrationOptions", "CandidatesStage", "DataStage", "SelectionStage", "UncertaintyStage"]


@dataclass(frozen=True)
class CalibrationOptions:
    """How a calibration runs (:func:`calibrate.report.calibrate`).

    Attributes
    ----------
    folds : int or None
        Number of cross-validation folds, in [2, n_points / 2]; None: chosen by
        :func:`calibrate.report.default_folds` from the rows (5, or half the rows under 10). [1]
    seed : int
        Seed of the folds (outer and nested inner ones), of the search subset and of the GP's subset.
    gp_max_train : int
        Training rows per fold of the GP discrepancy at most. [1]
    make_plots : bool
        Whether to draw the plots.
    search : SearchOptions
        How forward selection searches (:class:`calibrate.select.SearchOptions`), its convention
        included.
    requested_terms : int or None
        The most terms asked for when the rows support fewer (``search.max_terms`` is then lowered to what
        they support, :func:`calibrate.decidability.terms_supported`); None: as asked.
    """

    folds: int | None = None
    seed: int = 0
    gp_max_train: int = 300
    make_plots: bool = True
    search: SearchOptions = field(default_factory=SearchOptions)
    requested_terms: int | None = None

    @property
    def convention(self) -> str:
        """See :data:`physics.CONVENTIONS`."""
        return self.search.convention

    @property
    def candidate_search(self) -> SearchOptions:
        """How the candidates stage searches on all rows: as :attr:`search`, except on rows too few for
        nested cross-validation to weigh one term (``search.max_terms`` lowered to 0 from
        ``requested_terms``): a look, one step that scores every candidate as any step does (each fitted
        jointly with the declared parameters on the single level of folds the rows allow, judged on its
        held-out rows, charged by the score for its values) and claims none
        (:attr:`calibrate.search.SearchOptions.claim`). The candidates the rows lean to become rivals
        (:func:`calibrate.rivals.undecided_candidates`), so that the intervals hold them; without the
        look, 8 rows of friction up to 14x the physics at 80 % RH were answered by the physics alone, its
        interval at RH 0.7-0.8 covering 0.12-0.75 on 10 of 30 data sets. The nested cross-validation
        keeps :attr:`search`: nothing is searched inside its folds."""
        if self.search.max_terms == 0 and self.requested_terms:
            return replace(self.search, max_terms=1, claim=False)
        return self.search

    @classmethod
    def from_keywords(
        cls,
        folds: int | None = None,
        seed: int = 0,
        gp_max_train: int = 300,
        make_plots: bool = True,
        convention: str = physics.DEFAULT_CONVENTION,
        z_threshold: float = 3.0,
        max_terms: int = MAX_TERMS,
        max_search_rows: int = MAX_SEARCH_ROWS,
        family_alpha: float | None = FAMILY_ALPHA,
        scatter_rounds: int = SCATTER_ROUNDS,
    ) -> CalibrationOptions:
        """The options from :func:`calibrate.report.calibrate`'s keywords (described there)."""
        search = SearchOptions(z_threshold=z_threshold, max_terms=max_terms, max_rows=max_search_rows,
                               convention=convention, family_alpha=family_alpha,
                               scatter_rounds=scatter_rounds)
        return cls(folds, seed, gp_max_train, make_plots, search)


@dataclass(frozen=True)
class DataStage:
    """Stage 1: the checked data and the declared model on them.

    Attributes
    ----------
    dataset : Dataset
        The measurements.
    fit_parameters : list of str
        Declared parameters fitted (checked, without repeats).
    error_default : dict
        In-sample errors of the declared model with its default parameters.
    outer : list of numpy.ndarray
        Test rows of each outer fold.
    baseline : ModelCV
        The declared model fitted on all rows and on each outer fold's training rows.
    error_before : dict
        Held-out errors of ``baseline`` (the **before** figure).
    mu_before : numpy.ndarray
        μ of ``baseline``'s fit on all rows at every row. [1]
    measurement : MeasurementSystem or None
        Replicates, clips, constant data and order/time columns (:func:`calibrate.measurement.inspect`);
        ``dataset`` carries its design points and censored rows.
    """

    dataset: Dataset
    fit_parameters: list[str]
    error_default: dict[str, float]
    outer: list[np.ndarray] = field(repr=False)
    baseline: ModelCV
    error_before: dict[str, float]
    mu_before: np.ndarray = field(repr=False)
    measurement: MeasurementSystem | None = None

    def censored_with(self, terms: tuple, convention: str) -> DataStage:
        """The stage with its censored likelihood's scale that of the declared model and ``terms`` (the
        chosen ones), not of the declared model alone, whose residual holds what it lacks
        (:func:`calibrate.measurement.with_censor_scale`); itself without terms or clipped rows."""
        if not terms or self.dataset.censored is None:
            return self
        return replace(self, dataset=with_censor_scale(self.dataset, self.fit_parameters, convention, terms))


@dataclass(frozen=True)
class CandidatesStage:
    """Stage 2: the candidate terms searched by forward selection on all rows.

    Attributes
    ----------
    selection : Selection
        The terms chosen, every step with its candidates' scores, and the decision in words
        (:func:`calibrate.select.forward_select`).
    """

    selection: Selection

    @property
    def terms(self) -> tuple:
        """The terms chosen, in order."""
        return self.selection.terms


@dataclass(frozen=True)
class SelectionStage:
    """Stage 3: the selection judged held out, and the chosen terms fitted on all rows.

    Attributes
    ----------
    nested : NestedValidation
        The selection redone inside every outer fold (:func:`calibrate.select.nested_cross_validate`).
    gp : dict
        The Gaussian-process discrepancy baseline on the declared model
        (:func:`calibrate.discrepancy.gp_discrepancy`).
    final : FitResult
        The declared parameters and the chosen terms fitted on all rows (the declared fit when
        nothing was chosen).
    error_after_selection : dict
        Held-out errors of the chosen terms on the folds of the selection (optimistic).
    mu_after : numpy.ndarray
        μ of ``final`` at every row. [1]
    """

    nested: NestedValidation
    gp: dict[str, Any]
    final: FitResult
    error_after_selection: dict[str, float]
    mu_after: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class UncertaintyStage:
    """Stage 4: what scatters around the chosen model, and the calibrated model with its intervals.

    Attributes
    ----------
    final : FitResult
        The final fit: :attr:`SelectionStage.final`, refitted with each row weighted by its local
        scatter when the scatter model is not one spread everywhere (and the data declare no
        ``mu_measured_std``).
    mu_after : numpy.ndarray
        μ of ``final`` at every row. [1]
    outliers : dict
        :func:`calibrate.uncertainty.find_outliers` of the final model (``mask`` included).
    group_effects : list of GroupEffect
        Random effects of the factor columns (:mod:`calibrate.groups`).
    scatter : ScatterModel
        The scatter model, at the level of a new measurement's scatter.
    error_after : dict
        Held-out errors of the nested cross-validation (the **after** figure).
    robust_errors : dict
        ``before`` and ``after`` without the outlier rows, and ``excluded_rows`` [1].
    leftover : dict
        The GP on what the terms leave (:func:`calibrate.discrepancy.residual_gp`) with
        ``chosen_terms_z`` [1]; ``gp`` its state when it joins the model, else None.
    cloud : DataCloud or None
        The data cloud of the domain.
    pairs : list
        Columns that move together (:func:`calibrate.domain.confounded_pairs`).
    rivals : list of Rival
        Terms that fit about as well as a chosen one (:func:`calibrate.rivals.fit_rivals`).
    model : CalibratedModel
        The calibrated model, its rivals included.
    """

    final: FitResult
    mu_after: np.ndarray = field(repr=False)
    outliers: dict[str, Any] = field(repr=False)
    group_effects: list[GroupEffect]
    scatter: ScatterModel
    error_after: dict[str, float]
    robust_errors: dict[str, Any]
    leftover: dict[str, Any] = field(repr=False)
    cloud: DataCloud | None
    pairs: list[dict[str, Any]]
    rivals: list[Rival]
    model: CalibratedModel

    @property
    def inliers(self) -> np.ndarray:
        """Rows that are not outliers."""
        return ~self.outliers["mask"]

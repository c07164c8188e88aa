"""Step 7, the end of the pipeline: :func:`calibrate` runs every step once, in order, and reports.

One data set flows one way, each step a function of the previous step's result:

1. data (:mod:`calibrate.data`): parse and check every cell;
2. candidate terms (:mod:`calibrate.candidates`): named effects, parameter drifts, generic terms;
3. robust fit (:mod:`calibrate.fit`): the declared parameters on log μ with Huber's loss; its
   held-out error on k folds is the **before** figure;
4. forward selection (:mod:`calibrate.select`): terms added one at a time while cross-validation
   shows more than noise; then the whole selection repeated inside every fold (nested
   cross-validation), whose held-out error is the **after** figure;
5. uncertainty (:mod:`calibrate.uncertainty`): the final fit's sandwich covariance, outliers,
   the chi-square test against a declared noise, parameters that moved or sit on a bound; the
   calibrated model (:class:`calibrate.model.CalibratedModel`) with its 95 % prediction intervals
   and domain;
6. plots (:mod:`calibrate.plots`);

and, beside them, a Gaussian-process discrepancy baseline (:mod:`calibrate.discrepancy`).

In code these are four stage functions, each returning a frozen dataclass of :mod:`calibrate.stages`
(:func:`data_stage`, :func:`candidates_stage`, :func:`selection_stage`, :func:`uncertainty_stage`);
:func:`format_report` writes the report, numbers and words, from their results.

``error_before`` and ``error_after`` are plain errors of μ on held-out rows of the same k folds,
defined as before this pipeline; ``robust_errors`` gives them again without the outlier rows. The
chosen terms' own CV error on the folds that chose them (``error_after_selection``) is optimistic:
those folds also picked them among many candidates.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from microbearing import physics

from .censored import beyond_clip, measured_rows
from .data import Dataset, parse_csv, parse_rows
from .decidability import few_rows, rows_for_gp, rows_for_terms, terms_supported, undecided
from .discrepancy import gp_discrepancy, residual_gp, residual_gp_words
from .domain import DataCloud, confounded_pairs, confounding_words, edge_trends
from .fit import FitResult, check_fit_parameters, fit, predict_mu, prediction_errors
from .groups import describe_groups, fit_group_effect, why_not_fitted, within_groups
from .measurement import drift_words, inspect, lack_of_fit, with_censor_scale
from .measurement import folds as design_folds
from .model import CalibratedModel, RivalModel
from .plausibility import check_plausible
from .plots import calibration_plots
from .prose import code_columns, domain_report, in_sent_words, level_not_drift, rival_drivers, rival_words
from .rivals import Rival, fit_rivals, rival_json
from .scatter import ScatterModel, fit_scatter, noise_level
from .select import (
    REPORTED_CANDIDATES,
    Selection,
    WithinGroups,
    cross_validate,
    forward_select,
    held_out_of_chosen,
    held_out_within_groups,
    nested_cross_validate,
)
from .stages import CalibrationOptions, CandidatesStage, DataStage, SelectionStage, UncertaintyStage
from .tails import interval_form
from .uncertainty import find_outliers, noise_report, parameter_warnings

__all__ = [
    "DEFAULT_FOLDS",
    "MIN_ROWS",
    "PROGRESS_STAGES",
    "CalibrationOptions",
    "CalibrationReport",
    "calibrate",
    "candidates_stage",
    "check_request",
    "data_stage",
    "default_folds",
    "format_report",
    "selection_stage",
    "uncertainty_stage",
]

#: Fewest rows a calibration accepts (with honest, wide intervals and no effect claimed on so few). [1]
MIN_ROWS = 8

#: Fraction of ``progress`` reached at the end of each stage of :func:`calibrate`, in order. [1]
PROGRESS_STAGES = {
    "declared fit + CV": 0.02,
    "forward selection": 0.17,
    "nested CV": 0.8,
    "GP discrepancy": 0.9,
    "final fit, intervals, plots": 1.0,
}
# A GP discrepancy this much better (held out) than the calibrated model means something is left.
_GP_BETTER = 0.9


@dataclass(frozen=True)
class CalibrationReport:
    """Everything a calibration found.

    Attributes
    ----------
    n_points : int
        Measurements used. [1]
    fit_parameters : list of str
        Declared parameters fitted.
    error_default : dict
        In-sample errors of the declared model with its default parameters (``rmse`` [1],
        ``relative_rmse`` [1] on log μ, ``max_abs_error`` [1]).
    fitted_declared : dict
        ``{name: {"value", "std"}}`` of the declared-only fit (the "before" model), in their units.
    fitted_parameters : dict
        ``{name: {"value", "std"}}`` of the declared parameters in the calibrated model (``std``
        from the sandwich covariance).
    error_before : dict
        Held-out (k-fold) errors of the fitted declared model.
    error_after : dict
        Held-out errors of the calibrated model by nested cross-validation: each fold predicted by
        the model that the whole procedure (declared fit, forward selection, fit of the chosen
        terms) built on the other folds. Equal to ``error_before`` when no fold added a term.
    error_after_selection : dict
        Held-out errors of the chosen terms on the folds of the selection, over the rows it searched
        (all rows up to :data:`calibrate.select.MAX_SEARCH_ROWS`; ``error_before`` when nothing was
        added): optimistic, since the selection saw those folds.
    robust_errors : dict
        ``before`` and ``after`` as above without the outlier rows, and ``excluded_rows`` [1].
    effect_stability : dict
        How often the selection on each fold's training rows chose the same terms as on all rows
        (see :meth:`calibrate.select.NestedValidation.stability`).
    missing_effect : dict or None
        The first term added (see ``effects``); None when nothing beyond noise remains.
    effects : list of dict
        Every term added, in order: ``kind`` (``effect`` or ``drift``), ``name``, ``label``,
        ``title``, ``drivers``, ``formula``, ``parameters``, ``parameter_std``, ``parameter_units``,
        ``constants``, ``reference`` (a drift also ``parameter`` and ``law``).
    steps : list of dict
        Forward selection step by step: ``added`` (label or None for the step that stopped),
        ``errors`` (held-out errors on the search rows after the step), ``z``, ``z_needed``,
        ``candidates`` (the best scores of the step) and ``reason``.
    outliers : dict
        ``count``, ``threshold``, ``rows`` (row, mu_measured, mu_predicted, standardized_residual)
        and ``summary`` (see :func:`calibrate.uncertainty.find_outliers`).
    noise : dict or None
        Chi-square test against ``mu_measured_std`` (:func:`calibrate.uncertainty.noise_report`).
    warnings : list of str
        Parameters that moved beyond their interval or sit on a bound, a GP that does better.
    discrepancy_gp : dict
        Held-out errors and fitted kernel of the GP discrepancy baseline (on the declared model);
        and, for a GP on what the calibrated model's terms leave (:func:`calibrate.discrepancy.residual_gp`),
        ``calibrated_errors`` and ``calibrated_errors_without`` (nested held-out errors over the rows
        that are not outliers, with and without it), ``calibrated_z`` [1] (paired z of the decrease of
        the squared log error), ``chosen_terms_z`` [1] (the same test on the chosen terms refitted on
        each outer fold, run when the first passes), ``in_model`` (whether it is part of the
        calibrated model: both tests passed, on at least
        :func:`calibrate.decidability.rows_for_gp` rows) and ``rows_for_gp`` (those rows, when the
        first test passed on fewer: the GP was held back; else None) and ``clipped_rows`` (the rows
        clipped at a sensor's limit, when the first test passed on data with any: the GP was held back,
        since beside a clip the measured rows are a truncated sample; else None).
    candidates : list of dict
        The first step's candidates' cross-validated scores, the declared model first.
    decision : str
        What was added, step by step, and why the selection stopped.
    folds : int
        Number of cross-validation folds. [1]
    model : CalibratedModel
        The calibrated model, JSON-serializable.
    plots : dict of str to bytes
        PNG images (see :mod:`calibrate.plots`).
    rivals : list of dict
        Terms that fit the data about as well as a chosen one (:mod:`calibrate.rivals`), kept in the
        model's intervals: ``label``, ``gap_se`` [1], ``where`` (per driver scanned, see
        :func:`calibrate.rivals.where_they_part`) and ``statement`` in words.
    undecided : list of dict
        What the data leave open (a candidate just short of the threshold, a term added barely,
        rivals) with roughly where and how many more rows would settle it
        (:func:`calibrate.decidability.undecided`).
    groups : list of dict
        Per factor column (:mod:`calibrate.groups`): ``factor``, ``parameter`` (that varies between
        groups, or ``mu``), ``groups`` [1], ``spread_relative`` [1] and its 95 % interval
        ``spread_interval_relative`` [1], ``within_group_scatter_relative`` [1], ``levels`` (per label:
        ``relative_shift`` [1], ``std_log`` [1], ``rows`` [1]), ``restricted_log_likelihoods`` [1] of the
        random effect on each candidate parameter (the highest carries the spread) and ``summary`` in words.
    scatter : dict
        The scatter model (:mod:`calibrate.scatter`) as data, with ``summary`` in words.
    confounding : list of str
        Columns that move together, chosen terms whose driver may stand for another (:mod:`calibrate.domain`),
        and drifts chosen for their parameter's level, not a change (:func:`calibrate.prose.level_not_drift`).
    domain : dict
        ``columns`` of the data cloud, ``alpha`` [1] and ``summary`` of the domain rule in words.
    measurement_system : dict
        What the data say about the measurement system (:mod:`calibrate.measurement`): ``replicates``
        (pure error and lack of fit, or None), ``saturation`` (clips), ``constant``, ``sessions`` (order
        and time columns), ``drift`` (the instrument's, in words) and ``summary``, a list of sentences.
    """

    n_points: int
    fit_parameters: list[str]
    error_default: dict[str, float]
    fitted_declared: dict[str, dict[str, float]]
    fitted_parameters: dict[str, dict[str, float]]
    error_before: dict[str, float]
    error_after: dict[str, float]
    error_after_selection: dict[str, float]
    robust_errors: dict[str, Any]
    effect_stability: dict[str, Any]
    missing_effect: dict[str, Any] | None
    effects: list[dict[str, Any]]
    steps: list[dict[str, Any]]
    outliers: dict[str, Any]
    noise: dict[str, Any] | None
    warnings: list[str]
    discrepancy_gp: dict[str, Any]
    candidates: list[dict[str, Any]]
    decision: str
    folds: int
    model: CalibratedModel
    plots: dict[str, bytes] = field(repr=False)
    rivals: list[dict[str, Any]] = field(default_factory=list)
    undecided: list[dict[str, Any]] = field(default_factory=list)
    groups: list[dict[str, Any]] = field(default_factory=list)
    scatter: dict[str, Any] = field(default_factory=dict)
    confounding: list[str] = field(default_factory=list)
    domain: dict[str, Any] = field(default_factory=dict)
    measurement_system: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready result without the PNG bytes (``plots`` lists their names)."""
        return {
            "n_points": self.n_points,
            "fit_parameters": list(self.fit_parameters),
            "error_default": self.error_default,
            "fitted_declared": self.fitted_declared,
            "fitted_parameters": self.fitted_parameters,
            "error_before": self.error_before,
            "error_after": self.error_after,
            "error_after_selection": self.error_after_selection,
            "robust_errors": self.robust_errors,
            "effect_stability": self.effect_stability,
            "missing_effect": self.missing_effect,
            "effects": self.effects,
            "steps": self.steps,
            "outliers": {k: v for k, v in self.outliers.items() if k != "mask"},
            "noise": self.noise,
            "warnings": list(self.warnings),
            "discrepancy_gp": self.discrepancy_gp,
            "candidates": self.candidates,
            "decision": self.decision,
            "folds": self.folds,
            "model": self.model.to_json(),
            "plots": sorted(self.plots),
            "rivals": list(self.rivals),
            "undecided": list(self.undecided),
            "groups": self.groups,
            "scatter": self.scatter,
            "confounding": list(self.confounding),
            "domain": self.domain,
            "measurement_system": self.measurement_system,
        }

    def text(self) -> str:
        """The report in a few lines of plain text, for the command line."""

        def errors(e: Mapping[str, float]) -> str:
            return (
                f"rmse {e['rmse']:.4g}, relative rmse (log mu) {e['relative_rmse']:.4g}, "
                f"max abs {e['max_abs_error']:.4g}"
            )

        def estimates(values: Mapping[str, Mapping[str, float]], units: Mapping[str, str]) -> list[str]:
            return [f"  {n} = {v['value']:.6g} +/- {v['std']:.2g} [{units[n]}]" for n, v in values.items()]

        physics_units = {n: p.unit for n, p in physics.PARAMETERS.items()}
        lines = [
            f"{self.n_points} measurements, {self.folds}-fold cross-validation",
            f"declared model, default parameters (in-sample): {errors(self.error_default)}",
        ]
        if self.fitted_declared:
            lines.append("fitted declared parameters (before):")
            lines += estimates(self.fitted_declared, physics_units)
        lines.append(f"before (held out): {errors(self.error_before)}")
        if not self.effects:
            lines.append("missing effect: none")
        for k, effect in enumerate(self.effects):
            step = self.steps[k]
            lines.append(
                f"{'missing effect' if k == 0 else 'then'}: {effect['name']} ({effect['title']}) driven "
                f"by {', '.join(effect['drivers'])}; after this step (CV, search rows): "
                f"relative rmse {step['errors']['relative_rmse']:.4g}"
            )
            lines.append(f"  {effect['formula']}")
            lines += estimates(
                {
                    n: {"value": effect["parameters"][n], "std": effect["parameter_std"][n]}
                    for n in effect["parameters"]
                },
                effect["parameter_units"],
            )
        if self.effects and self.fitted_parameters:
            lines.append("declared parameters of the calibrated model (sandwich std):")
            lines += estimates(self.fitted_parameters, physics_units)
        lines.append(
            f"after (held out, nested CV: the selection redone within each fold): {errors(self.error_after)}"
        )
        if self.effects:
            lines.append(
                f"after on the folds that chose the terms (optimistic): {errors(self.error_after_selection)}"
            )
        robust = self.robust_errors
        lines.append(
            f"without the {robust['excluded_rows']} outlier row(s): before relative rmse "
            f"{robust['before']['relative_rmse']:.4g}, after {robust['after']['relative_rmse']:.4g}"
        )
        lines.append(f"outliers: {self.outliers['summary']}")
        if self.noise is not None:
            lines.append(f"noise: {self.noise['statement']}")
        lines.append(f"stability: {self.effect_stability['summary']}")
        lines.append(f"GP discrepancy baseline (held out): {errors(self.discrepancy_gp['errors'])}")
        lines += [f"undecided: {u['statement']}" for u in self.undecided]
        lines += [f"groups: {g['summary']}" for g in self.groups]
        if self.scatter:
            lines.append(f"scatter: {self.scatter['summary']}")
        lines += [f"confounding: {c}" for c in self.confounding]
        if self.domain:
            lines.append(f"domain: {self.domain['summary']}")
        lines += [f"measurement: {line}" for line in self.measurement_system.get("summary", [])]
        lines += [f"warning: {w}" for w in self.warnings]
        lines.append(f"decision: {self.decision}")
        return "\n".join(lines)


def _as_dataset(data, fixed) -> Dataset:
    if isinstance(data, Dataset):
        if fixed:
            raise ValueError("fixed: give fixed values when parsing the data, not with a Dataset")
        return data
    if isinstance(data, str | bytes):
        return parse_csv(data, fixed)
    return parse_rows(data, fixed)


def _values(values: Mapping[str, float], stds: Mapping[str, float]) -> dict[str, dict[str, float]]:
    return {n: {"value": float(values[n]), "std": float(stds[n])} for n in values}


def check_request(dataset: Dataset, fit_parameters: Sequence[str], folds: int) -> None:
    """Check a calibration request before the work starts.

    Parameters
    ----------
    dataset : Dataset
        Parsed measurements.
    fit_parameters : sequence of str
        Declared parameters to fit.
    folds : int
        Number of cross-validation folds. [1]

    Raises
    ------
    calibrate.data.DataError
        For implausible values (:func:`calibrate.plausibility.check_plausible`), naming each column.
    ValueError
        Starting with the offending field (``data``, ``folds`` or ``fit_parameters``).
    """
    check_plausible(dataset)
    if dataset.n_points < MIN_ROWS:
        raise ValueError(f"data must have at least {MIN_ROWS} rows; got {dataset.n_points}")
    if not 2 <= folds <= dataset.n_points // 2:
        raise ValueError(f"folds must be in [2, {dataset.n_points // 2}] (half the rows); got {folds}")
    names = check_fit_parameters(dataset, fit_parameters)
    needed = rows_needed(len(names), folds)
    if dataset.n_points < needed:
        raise ValueError(
            f"data must have at least {needed} rows for {folds}-fold nested cross-validation with "
            f"{len(names)} fitted parameter(s); got {dataset.n_points}"
        )


#: Cross-validation folds when the caller does not choose (fewer with fewer than twice as many rows).
DEFAULT_FOLDS = 5


def default_folds(n_points: int) -> int:
    """Folds of a calibration whose caller does not choose: 5, or half the rows when there are fewer
    than 10 (a fold holds at least two rows), so that every data set of :data:`MIN_ROWS` rows is answered.

    Examples
    --------
    >>> default_folds(200), default_folds(9), default_folds(8)
    (5, 4, 4)
    """
    return min(DEFAULT_FOLDS, max(2, n_points // 2))


def rows_needed(n_fit_parameters: int, folds: int) -> int:
    """Fewest rows for nested cross-validation of the declared model (fewer than the search needs for
    :data:`MAX_TERMS` terms: it then adds as many as the rows support,
    :func:`calibrate.decidability.terms_supported`, and says so).

    Examples
    --------
    >>> rows_needed(2, 5), rows_needed(2, 2)
    (8, 16)
    """
    return max(MIN_ROWS, rows_for_terms(n_fit_parameters, folds, 0))


def calibrate(
    data,
    fit_parameters: Sequence[str] = (),
    fixed: Mapping[str, Any] | None = None,
    *,
    options: CalibrationOptions | None = None,
    progress: Callable[[float], None] | None = None,
    **keywords: Any,
) -> CalibrationReport:
    """Calibrate the declared model on measurements, add the terms it misses, report.

    The stages (:mod:`calibrate.stages`) run in order, each a function of the ones before:
    :func:`data_stage`, :func:`candidates_stage`, :func:`selection_stage`, :func:`uncertainty_stage`;
    then the plots, and :func:`format_report` writes the report from them.

    Parameters
    ----------
    data : Dataset, str, bytes or sequence of mapping
        Measurements: a checked :class:`Dataset`, CSV text, or JSON-like rows.
    fit_parameters : sequence of str
        Declared physics parameters to fit, e.g. ``["mu_pivot", "adhesion_energy_J_m2"]``.
    fixed : mapping, optional
        Physics parameters fixed for every row (not with a ``Dataset``).
    options : CalibrationOptions, optional
        Every option at once (then no keywords).
    progress : callable, optional
        Called with the fraction done, 0..1, never decreasing (stages in :data:`PROGRESS_STAGES`).
    **keywords
        The options one by one instead (:meth:`CalibrationOptions.from_keywords`):

        - ``folds`` (int): number of cross-validation folds, in [2, n_points / 2], default
          :func:`default_folds` (5, or half the rows when there are fewer than 10) [1];
        - ``seed`` (int): seed of the folds (outer and nested inner ones), of the search subset and of
          the GP's subset, default 0;
        - ``gp_max_train`` (int): training rows per fold of the GP discrepancy at most, default 300 [1];
        - ``make_plots`` (bool): whether to draw the plots, default True;
        - ``convention`` (str): see :data:`physics.CONVENTIONS`;
        - ``z_threshold`` (float): least paired z of a candidate's held-out improvement (see
          :mod:`calibrate.select`), default 3 [1];
        - ``max_terms`` (int): most terms forward selection adds [1];
        - ``max_search_rows`` (int): rows the selection searches on at most (a random subset) [1];
        - ``family_alpha`` (float or None): chance per selection step that any candidate passes on
          noise alone; None: ``z_threshold`` alone decides (see :mod:`calibrate.select`) [1];
        - ``scatter_rounds`` (int): selections at most, each weighted by the scatter model of the one
          before (1: unweighted; see :func:`calibrate.select.forward_select`) [1].

    Returns
    -------
    CalibrationReport

    Raises
    ------
    calibrate.data.DataError
        For bad rows, cells or columns (every one listed).
    ValueError
        For too few rows, bad ``folds`` or ``fit_parameters``.
    TypeError
        For an unknown keyword, or keywords beside ``options``.
    """
    if options is not None and keywords:
        raise TypeError(f"calibrate: give options or keywords, not both; got {', '.join(keywords)}")
    options = options or CalibrationOptions.from_keywords(**keywords)
    report = progress or (lambda fraction: None)
    if options.convention not in physics.CONVENTIONS:
        raise ValueError(
            f"convention must be one of {', '.join(physics.CONVENTIONS)}; got {options.convention!r}")
    dataset = _as_dataset(data, fixed)
    if options.folds is None:
        options = replace(options, folds=default_folds(dataset.n_points))
    check_request(dataset, fit_parameters, options.folds)
    # Few rows: the search adds only as many terms as nested cross-validation can fit and judge on them.
    supported = terms_supported(dataset.n_points, len(check_fit_parameters(dataset, fit_parameters)),
                                options.folds, options.search.max_terms)
    if supported < options.search.max_terms:
        options = replace(options, search=replace(options.search, max_terms=supported),
                          requested_terms=options.search.max_terms)
    report(0.0)
    ends = list(PROGRESS_STAGES.values())

    def stage(i: int) -> Callable[[float], None]:
        start = 0.0 if i == 0 else ends[i - 1]
        return lambda f: report(start + (ends[i] - start) * min(max(f, 0.0), 1.0))

    declared = data_stage(dataset, fit_parameters, options)
    stage(0)(1.0)
    candidates = candidates_stage(declared, options, stage(1))
    stage(1)(1.0)
    declared = declared.censored_with(candidates.terms, options.convention)  # clips: the chosen law's scale
    selection = selection_stage(declared, candidates, options, stage(2), stage(3))
    uncertainty = uncertainty_stage(declared, candidates, selection, options)
    plots: dict[str, bytes] = {}
    if options.make_plots:
        plots = calibration_plots(
            declared.dataset, uncertainty.model, declared.mu_before, uncertainty.mu_after,
            uncertainty.outliers["mask"],
            {"before": declared.error_before, "after": uncertainty.error_after,
             "robust": uncertainty.robust_errors}, [t.label for t in candidates.terms],
        )
    report(1.0)
    return format_report(declared, candidates, selection, uncertainty, options, plots)


def data_stage(dataset: Dataset, fit_parameters: Sequence[str], options: CalibrationOptions) -> DataStage:
    """Stage 1: the declared model on the checked data, fitted on all rows and cross-validated.

    Parameters
    ----------
    dataset : Dataset
        Measurements, checked (:func:`check_request`).
    fit_parameters : sequence of str
        Declared parameters to fit.
    options : CalibrationOptions
        ``folds``, ``seed`` and the convention act here.

    Returns
    -------
    DataStage
    """
    fit_parameters = check_fit_parameters(dataset, fit_parameters)
    convention = options.convention
    # Replicates, clips, order/time columns (calibrate.measurement): folds keep a point whole; clips censored.
    system = inspect(dataset, options.folds)
    dataset = with_censor_scale(system.apply(dataset), fit_parameters, convention)
    measured = dataset.mu_measured
    error_default = prediction_errors(predict_mu(dataset, {}, convention=convention), measured)
    outer = design_folds(dataset, options.folds, options.seed)
    baseline = cross_validate(dataset, fit_parameters, (), outer, convention=convention)
    mu_before = predict_mu(dataset, baseline.full.declared, convention=convention)
    return DataStage(dataset, fit_parameters, error_default, outer, baseline,
                     prediction_errors(baseline.oof_mu, measured), mu_before, system)


def candidates_stage(declared: DataStage, options: CalibrationOptions,
                     progress: Callable[[float], None]) -> CandidatesStage:
    """Stage 2: forward selection over the candidate terms on all rows
    (:func:`calibrate.select.forward_select`), with ``progress`` called with its fraction done. With
    factor columns the search runs on the measurements with each group's level taken out
    (:func:`calibrate.groups.within_groups`): offsets between specimens are not scatter to an effect."""
    searched, _ = within_groups(declared.dataset, declared.mu_before)
    return CandidatesStage(forward_select(searched, declared.fit_parameters, options.folds,
                                          options.seed, options.candidate_search, progress))


def selection_stage(declared: DataStage, candidates: CandidatesStage, options: CalibrationOptions,
                    nested_progress: Callable[[float], None],
                    gp_progress: Callable[[float], None]) -> SelectionStage:
    """Stage 3: the selection redone inside every outer fold (the **after** figure), the GP discrepancy
    baseline, and the chosen terms fitted on all rows; each progress callable is called with the
    fraction done of its part, then 1."""
    dataset, fit_parameters, baseline = declared.dataset, declared.fit_parameters, declared.baseline
    selection = candidates.selection
    # Each outer fold's search starts weighted by the scatter that weighted the search on all rows, and
    # keeps it only when its own residual confirms it (calibrate.select.forward_select).
    nested = nested_cross_validate(dataset, fit_parameters, baseline, options.seed, options.search,
                                   nested_progress, selection.scatter)
    nested_progress(1.0)
    gp = gp_discrepancy(dataset, baseline, options.gp_max_train, options.seed, progress=gp_progress)
    gp_progress(1.0)
    terms = selection.terms
    if terms:
        final = fit(dataset, fit_parameters, terms, start=selection.model.full.declared,
                    start_terms=selection.model.full.term_values, convention=options.convention)
        error_after_selection = prediction_errors(selection.model.oof_mu, dataset.mu_measured[selection.rows])
    else:
        final, error_after_selection = baseline.full, declared.error_before
    mu_after = predict_mu(dataset, final.declared, terms, final.term_values, convention=options.convention)
    return SelectionStage(nested, gp, final, error_after_selection, mu_after)


def uncertainty_stage(declared: DataStage, candidates: CandidatesStage, selection: SelectionStage,
                      options: CalibrationOptions) -> UncertaintyStage:
    """Stage 4: outliers, group effects, the scatter model (and the fit it weights), a GP on what the
    terms leave, the noise of a new measurement, the calibrated model and its rivals.

    Parameters
    ----------
    declared, candidates, selection : DataStage, CandidatesStage, SelectionStage
        The stages before.
    options : CalibrationOptions
        ``folds``, ``seed``, ``gp_max_train`` and the convention act here.

    Returns
    -------
    UncertaintyStage
    """
    dataset, convention = declared.dataset, options.convention
    measured, terms, nested = dataset.mu_measured, candidates.terms, selection.nested
    final, mu_after = selection.final, selection.mu_after
    sent = declared.measurement.kept if declared.measurement else None  # rows numbered as sent
    outliers = find_outliers(dataset, mu_after, final.residual, final.scale, sent)
    # Groups: the spread of a parameter (or mu) between the labels of each factor column (calibrate.groups);
    # the held-out residual loses each row's level (from its fold's training rows: held_out_within_groups).
    group_effects, group_shift = _group_effects(dataset, final, terms, mu_after, ~outliers["mask"],
                                                convention)
    held_out = np.log(measured / held_out_of_chosen(nested, dataset, declared.fit_parameters, final,
                                                    declared.outer, convention)) - group_shift
    if (within := held_out_within_groups(dataset, declared.fit_parameters, final, declared.outer,
                                         convention)) is not None:
        held_out = np.where(np.isfinite(within.held_out), within.held_out, held_out)
    # Scatter that depends on the inputs (calibrate.scatter), chosen by cross-validation on the
    # held-out residual; when it is not one spread everywhere, the model is refitted with each row
    # weighted by its local scatter (unless the data declare mu_measured_std, which weighs them
    # already), and outliers are judged against the local scatter.
    varying = {k: v for k, v in dataset.columns().items() if v.dtype != bool and np.unique(v).size > 1}
    values = measured_rows(dataset.censored, dataset.n_points)  # a clipped reading's residual is not scatter
    scatter = fit_scatter({k: v[values] for k, v in varying.items()}, held_out[values], options.folds,
                          options.seed)
    reweighted = False  # whether final below is the weighted refit (within was read from the unweighted fit)
    if scatter.kind != "constant":
        local = scatter.std_log(varying, measured.shape)
        if dataset.mu_measured_std is None:
            weighted = replace(dataset, mu_measured_std=measured * local / float(np.median(local)))
            final = fit(weighted, declared.fit_parameters, terms, start=final.declared,
                        start_terms=final.term_values, convention=convention)
            reweighted = True
            mu_after = predict_mu(dataset, final.declared, terms, final.term_values, convention=convention)
            outliers = find_outliers(dataset, mu_after, final.residual, final.scale, sent)
        else:
            outliers = find_outliers(dataset, mu_after, np.log(mu_after / measured) / local, 1.0, sent)
    inliers = ~outliers["mask"]
    robust_errors = {
        "before": prediction_errors(declared.baseline.oof_mu[inliers], measured[inliers]),
        "after": prediction_errors(nested.oof_mu[inliers], measured[inliers]),
        "excluded_rows": int(outliers["count"]),
    }
    # What the terms leave: a GP on the residual of each outer fold's own model, judged on its held-out
    # rows; part of the model only when it beats the terms alone there.
    # A clipped reading is not a value: what the terms leave is read on the measured rows, and the noise
    # counts a clipped row by its side of the clip (calibrate.censored.residual_variance).
    # The GP reads values: a clipped row enters at the mean true reading beyond its clip under the model
    # (calibrate.censored.beyond_clip); on the measured rows alone it learned the truncation near the clip.
    values = inliers & measured_rows(dataset.censored, dataset.n_points)
    read = replace(dataset, censored=None, mu_measured=np.exp(-group_shift)  # each row's group level out
                   * beyond_clip(mu_after, measured, dataset.censored, dataset.censor_scale))
    leftover = residual_gp(read, declared.outer, nested.fold_mu, mu_after, inliers, options.gp_max_train,
                           options.seed)
    leftover = _confirm_gp(declared, final, leftover, mu_after, inliers, options, read, within,
                           reweighted)
    noise_std_log, scatter = noise_level(scatter, leftover["gp"], held_out, inliers, varying, measured.shape,
                                          dataset.censored)
    # The interval's form: the scatter's degrees of freedom and the residuals' tails (calibrate.tails),
    # read on the measured rows (a clipped row's residual is its distance to the clip, not a tail). The
    # tails are read on the residual standardized by the scatter model (a spread that varies is not a
    # tail); with a GP the residual also holds what the GP explains, and the Gaussian form stands.
    standardized = (held_out * noise_std_log / scatter.std_log(varying, measured.shape))[
        measured_rows(dataset.censored, dataset.n_points)]
    scatter = replace(scatter, form=interval_form(standardized if leftover["gp"] is None else held_out[:0],
                                                  values, noise_std_log, len(final.names)))
    cloud = DataCloud.from_columns(varying, options.seed)
    model = CalibratedModel.from_fit(final, dataset, convention, noise_std_log, discrepancy=leftover["gp"],
                                     groups=group_effects, scatter=scatter, cloud=cloud)
    model = replace(model, edge_trends=edge_trends(varying, held_out, values, model=model))
    # Rivals: terms that fit about as well as a chosen one, and terms on a column that moves with one the
    # model reads (calibrate.rivals): the interval holds their envelope.
    pairs = confounded_pairs(varying)
    rivals = fit_rivals(dataset, declared.fit_parameters, candidates.selection, final, convention,
                        pairs=pairs, few_rows=options.requested_terms is not None)
    if rivals:
        model = replace(model, rivals=[RivalModel.from_json(rival_json(r)) for r in rivals])
    return UncertaintyStage(final, mu_after, outliers, group_effects, scatter,
                            prediction_errors(nested.oof_mu, measured), robust_errors, leftover, cloud, pairs,
                            rivals, model)


def format_report(declared: DataStage, candidates: CandidatesStage, selection: SelectionStage,
                  uncertainty: UncertaintyStage, options: CalibrationOptions,
                  plots: dict[str, bytes]) -> CalibrationReport:
    """The report, numbers and words, written from the stages' results (and the plots drawn from them)."""
    dataset, fit_parameters, baseline = declared.dataset, declared.fit_parameters, declared.baseline
    found, final, model = candidates.selection, uncertainty.final, uncertainty.model
    terms, leftover, error_after = found.terms, uncertainty.leftover, uncertainty.error_after
    rival_list = rival_words(dataset, model, uncertainty.rivals)
    stability = selection.nested.stability(terms)
    gp = {
        **selection.gp,
        "calibrated_errors": leftover["errors"],
        "calibrated_errors_without": leftover["errors_without"],
        "calibrated_z": leftover["z"],
        "chosen_terms_z": leftover["chosen_terms_z"],
        "in_model": leftover["helps"],
        "rows_for_gp": leftover.get("rows_for_gp"),
        "clipped_rows": leftover.get("clipped_rows"),
    }
    effects = [
        {**term.describe(values, std), "label_as_sent": in_sent_words(dataset, term.label)}
        for term, values, std in zip(terms, final.term_values, final.term_std(), strict=True)
    ]
    searched = dataset.subset(found.rows)
    steps = [
        {
            "added": None if step.chosen is None else step.chosen.term.label,
            "errors": prediction_errors(
                (step.current if step.chosen is None else step.chosen).oof_mu, searched.mu_measured
            ),
            "z": None if step.chosen is None else step.chosen.z,
            "z_needed": step.z_needed,
            "candidates": [c.summary(searched) for c in [step.current, *step.ranked[:REPORTED_CANDIDATES]]],
            "reason": step.reason,
        }
        for step in found.steps
    ]
    confounding = confounding_words(uncertainty.pairs, [t.drivers[0] for t in terms]) + rival_drivers(found)
    return CalibrationReport(
        n_points=dataset.n_points,
        fit_parameters=list(fit_parameters),
        error_default=declared.error_default,
        fitted_declared=_values(baseline.full.declared, baseline.full.declared_std),
        fitted_parameters=_values(final.declared, final.declared_std),
        error_before=declared.error_before,
        error_after=error_after,
        error_after_selection=selection.error_after_selection,
        robust_errors=uncertainty.robust_errors,
        effect_stability=stability,
        missing_effect=effects[0] if effects else None,
        effects=effects,
        steps=steps,
        outliers=uncertainty.outliers,
        noise=noise_report(dataset, uncertainty.mu_after, len(final.names), uncertainty.inliers),
        warnings=_warnings(declared, uncertainty, gp),
        discrepancy_gp=gp,
        candidates=steps[0]["candidates"] if steps else [],
        decision=in_sent_words(dataset, found.reason),
        folds=options.folds,
        model=model,
        plots=plots,
        rivals=rival_list,
        undecided=[{**u, "statement": in_sent_words(dataset, u["statement"])} for u in undecided(
            dataset, found, stability, rival_list, fit_parameters, model.noise_std_log, options.convention)
                   + _few_rows(dataset, fit_parameters, options, found, uncertainty.rivals)],
        groups=describe_groups(uncertainty.group_effects) + [
            {"factor": name, "summary": f"{name}: {why_not_fitted(labels)}"}
            for name, labels in dataset.factors.items() if why_not_fitted(labels)],
        scatter={**uncertainty.scatter.to_json(), "summary": _scatter_words(uncertainty.scatter)},
        confounding=confounding + level_not_drift(terms, final.term_values, final.term_std()),
        domain=domain_report(dataset, uncertainty.cloud, uncertainty.model.domain),
        measurement_system=_measurement_system(declared, uncertainty, effects),
    )


def _measurement_system(declared: DataStage, uncertainty: UncertaintyStage,
                        effects: list[dict[str, Any]]) -> dict[str, Any]:
    """What the data say about the measurement system (:mod:`calibrate.measurement`), with the lack of
    fit of the calibrated model over the design points."""
    system, dataset, final = declared.measurement, declared.dataset, uncertainty.final
    lof = lack_of_fit(dataset, np.log(dataset.mu_measured / uncertainty.mu_after), len(final.names),
                      ~uncertainty.outliers["mask"])
    drift = drift_words(effects, system.clock)
    return {
        "replicates": None if lof is None else lof.to_json(),
        "saturation": [vars(clip) for clip in system.saturation],
        "unit_slips": [slip.to_json() for slip in system.slips],
        "constant": system.constant,
        "sessions": list(system.sessions),
        "clock": dict(system.clock),
        "drift": drift,
        "summary": system.words() + ([] if lof is None else [lof.words()]) + drift,
    }


def _scatter_words(scatter: ScatterModel) -> str:
    """The scatter model in words, with the form of the interval (calibrate.tails) when it has one."""
    return scatter.summary() + ("" if scatter.form is None else
                                f"; {scatter.form.words(varies=scatter.kind != 'constant')}")


def _few_rows(dataset: Dataset, fit_parameters: Sequence[str], options: CalibrationOptions,
              selection: Selection, rivals: Sequence[Rival]) -> list[dict]:
    """The report's item when the rows supported fewer terms than asked for (see :func:`calibrate`),
    naming the candidates of the step that stopped held as rivals (added, on no confounded column)."""
    most = options.requested_terms or options.search.max_terms
    leaning = [(r.term.label, -r.gap_se) for r in rivals if r.undecided]
    z_needed = selection.steps[-1].z_needed if selection.steps else None
    item = few_rows(dataset.n_points, len(fit_parameters), options.folds, options.search.max_terms, most,
                    leaning, z_needed)
    return [] if item is None else [item]


def _warnings(declared: DataStage, uncertainty: UncertaintyStage, gp: Mapping[str, Any]) -> list[str]:
    """Implausible values, parameters that moved or sit on a bound, code-like columns, and GPs that do
    better than the calibrated model."""
    dataset, leftover, error_after = declared.dataset, uncertainty.leftover, uncertainty.error_after
    warnings = check_plausible(dataset) + parameter_warnings(declared.baseline.full, uncertainty.final)
    warnings += code_columns(dataset)
    # On fewer rows than weigh a GP's hyperparameters its held-out errors say nothing of what remains.
    weighed = dataset.n_points >= rows_for_gp(len(declared.fit_parameters), len(declared.outer),
                                              len(gp["features"]))
    # Both errors read a clipped row's reading as a value: the model predicts the true mu beyond the clip,
    # a GP on the readings learns the clip, and its lower error is the clip (said by the measurement
    # system), not something a term could name (a ceiling clip of 30 points x 4: 0.045 against 0.112).
    clipped = not bool(np.all(measured_rows(dataset.censored, dataset.n_points)))
    if weighed and not clipped and gp["errors"]["relative_rmse"] < _GP_BETTER * error_after["relative_rmse"]:
        warnings.append(
            f"a Gaussian-process discrepancy predicts held-out rows better than the calibrated model "
            f"(relative rmse {gp['errors']['relative_rmse']:.3g} vs {error_after['relative_rmse']:.3g}): "
            f"something remains that no candidate term names"
        )
    return warnings + residual_gp_words(leftover, dataset.n_points)


def _confirm_gp(declared: DataStage, final: FitResult, leftover: dict[str, Any], mu_after: np.ndarray,
                inliers: np.ndarray, options: CalibrationOptions, read: Dataset,
                within: WithinGroups | None, reweighted: bool) -> dict[str, Any]:
    """A GP that helped the nested folds' models joins only if it helps the chosen model too: a fold whose
    selection missed a term the data need leaves a residual the GP takes up, and the GP would join a model
    (with that term) it does not help, bending it toward noise. So the same GP test is run on the held-out
    residual of the chosen terms refitted on each outer fold's training rows (with each group's level from
    them when the search fits levels; the declared model's folds when nothing was chosen). ``chosen_terms_z``
    [1] is that test's paired z (None if the first did not pass); ``read``: the data as the GP reads them.

    ``within``: :func:`held_out_within_groups` as stage 4 read it for the scatter (None without groups), from
    the unweighted fit; ``reweighted``: stage 4 then refitted ``final`` with the scatter's weights, and the
    folds are refitted here from that fit (its values as the start, its Huber scale), as the branch without
    groups refits them from it. The two readings differ only there (the same terms and data)."""
    if not leftover["helps"]:
        return {**leftover, "chosen_terms_z": None}
    clipped = declared.dataset.censored
    if clipped is not None and np.any(clipped != 0):
        # A GP reads values; a clipped row has none, and the measured rows beside a clip are a truncated
        # sample (those whose scatter fell on the near side). Held out, either reading of them rewards a
        # GP that learns the truncation, and its white noise, fitted beside rows read without scatter,
        # comes out below the reading's (clip seed 1 of bench/measurement_system.py: 2.1 % for a true
        # 3 %, coverage 0.83). The terms take the censored likelihood; the GP is held back.
        return {**leftover, "helps": False, "gp": None, "chosen_terms_z": None,
                "clipped_rows": int(np.sum(clipped != 0))}
    needed = rows_for_gp(len(declared.fit_parameters), options.folds, len(leftover["features"]))
    if int(np.sum(inliers)) < needed:
        # Too few rows to weigh the GP's hyperparameters: it would pass through the rows (decidability).
        return {**leftover, "helps": False, "gp": None, "chosen_terms_z": None, "rows_for_gp": needed}
    if within is not None and reweighted:
        within = held_out_within_groups(declared.dataset, declared.fit_parameters, final, declared.outer,
                                        options.convention)
    if within is not None:  # each fold's models carry each group's level from its training rows
        chosen, read = within.cv, replace(read, mu_measured=declared.dataset.mu_measured)
    elif final.terms:
        chosen = cross_validate(declared.dataset, declared.fit_parameters, final.terms, declared.outer,
                                scale=final.scale, start=final.declared, start_terms=final.term_values,
                                precise=False, convention=options.convention)
    else:
        chosen = declared.baseline
    again = residual_gp(read, declared.outer, chosen.fold_mu, mu_after, inliers,
                        options.gp_max_train, options.seed)
    if again["helps"]:
        return {**leftover, "chosen_terms_z": again["z"]}
    return {**leftover, "helps": False, "gp": None, "chosen_terms_z": again["z"]}


def _group_effects(dataset: Dataset, final, terms, mu_after: np.ndarray, inliers: np.ndarray,
                   convention: str) -> tuple[list, np.ndarray]:
    """Random effects of every factor column (in turn, each on what the previous ones leave) and the
    shift of log mu they give every row. [1]"""
    shift = np.zeros(dataset.n_points)
    if not dataset.factors:
        return [], shift
    sensitivities = {}
    for name, value in final.declared.items():
        step = 1e-4
        with np.errstate(all="ignore"):
            moved = predict_mu(dataset, {**final.declared, name: value * (1 + step)}, terms,
                               final.term_values, convention=convention)
        s = np.log(moved / mu_after) / np.log1p(step)
        if np.all(np.isfinite(s)):
            sensitivities[name] = s
    effects = []
    residual = np.log(dataset.mu_measured / mu_after)
    for factor, labels in dataset.factors.items():
        effect = None if why_not_fitted(labels) else fit_group_effect(factor, labels, residual - shift,
                                                                     sensitivities, inliers)
        if effect is None:
            continue
        s = np.ones(dataset.n_points) if effect.parameter == "mu" else sensitivities[effect.parameter]
        shift = shift + effect.shift(labels, s)[0]
        effects.append(effect)
    return effects, shift

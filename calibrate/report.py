"""The calibration loop and its report: :func:`calibrate`.

1. Residual of the declared model with its default parameters.
2. Fit of the declared parameters named in ``fit_parameters`` (bounded least
   squares on log μ); its held-out error is the **before** figure.
3. Search for the missing effect (:func:`calibrate.discover.discover`).
4. Nested cross-validation of steps 2-3 and 5
   (:func:`calibrate.discover.nested_cross_validate`): the search repeated on
   the training rows of every fold, the effect it chose fitted there and the
   fold's rows predicted; the error of those predictions is the **after**
   figure, and the share of folds that chose the same effect its stability.
5. The chosen effect fitted jointly with the declared parameters on all rows:
   the calibrated model (:class:`calibrate.model.CalibratedModel`).
6. A Gaussian-process discrepancy baseline (:func:`calibrate.discrepancy.gp_discrepancy`).
7. Plots of the residual against its driver, before and after, as PNG bytes.

Every error is measured on held-out rows of the same k folds. The chosen
effect's own CV error on those folds (``error_after_selection``) is reported
too, but it is optimistic: the folds that measure it also chose it among a few
dozen candidates.
"""

from __future__ import annotations

import io
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import physics

from .data import Dataset, parse_csv, parse_rows
from .discover import Discovery, cross_validate_baseline, discover, nested_cross_validate
from .discrepancy import gp_discrepancy
from .fit import check_fit_parameters, fit, predict_mu, prediction_errors
from .model import CalibratedModel

__all__ = ["CalibrationReport", "calibrate", "check_request", "MIN_ROWS", "PROGRESS_STAGES"]

#: Fewest rows a calibration accepts: k-fold CV needs a few rows per fold. [1]
MIN_ROWS = 10

#: Fraction of ``progress`` reached at the end of each stage of :func:`calibrate`, in order. [1]
PROGRESS_STAGES = {"declared fit + CV": 0.02, "effect discovery": 0.17, "nested CV": 0.75,
                   "GP discrepancy": 0.9, "final fit, plots": 1.0}


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
        ``{name: {"value", "std"}}`` of the declared parameters in the calibrated model.
    error_before : dict
        Held-out (k-fold) errors of the fitted declared model.
    error_after : dict
        Held-out errors of the calibrated model by nested cross-validation: each fold predicted by
        the model that the whole procedure (declared fit, effect search, fit of the chosen effect)
        built on the other folds. Equal to ``error_before`` when no fold added an effect.
    error_after_selection : dict
        Held-out errors of the chosen effect on the same folds that chose it (``error_before``
        when nothing was added): optimistic, since those folds also picked it among the
        candidates; the gap to ``error_after`` measures that selection bias.
    effect_stability : dict
        How often the search on each fold's training rows chose the same effect as on all rows:
        ``folds``, ``agreeing``, ``choices`` (per fold ``{"effect", "drivers"}``) and ``summary``
        (see :meth:`calibrate.discover.NestedValidation.stability`).
    missing_effect : dict or None
        ``name``, ``title``, ``drivers``, ``formula``, ``parameters``, ``parameter_std``,
        ``parameter_units``, ``reference``; None when nothing beyond noise remains.
    discrepancy_gp : dict
        Held-out errors and fitted kernel of the GP discrepancy baseline.
    candidates : list of dict
        Every candidate's cross-validated score (see :meth:`CandidateScore.summary`).
    decision : str
        Why the effect was chosen, or why nothing was added.
    folds : int
        Number of cross-validation folds. [1]
    model : CalibratedModel
        The calibrated model, JSON-serializable.
    plots : dict of str to bytes
        PNG images: ``residual_before`` and ``residual_after`` against the effect's driver, or
        ``residual`` against every varying column when nothing was added.
    """

    n_points: int
    fit_parameters: list[str]
    error_default: dict[str, float]
    fitted_declared: dict[str, dict[str, float]]
    fitted_parameters: dict[str, dict[str, float]]
    error_before: dict[str, float]
    error_after: dict[str, float]
    error_after_selection: dict[str, float]
    effect_stability: dict[str, Any]
    missing_effect: dict[str, Any] | None
    discrepancy_gp: dict[str, Any]
    candidates: list[dict[str, Any]]
    decision: str
    folds: int
    model: CalibratedModel
    plots: dict[str, bytes] = field(repr=False)

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
            "effect_stability": self.effect_stability,
            "missing_effect": self.missing_effect,
            "discrepancy_gp": self.discrepancy_gp,
            "candidates": self.candidates,
            "decision": self.decision,
            "folds": self.folds,
            "model": self.model.to_json(),
            "plots": sorted(self.plots),
        }

    def text(self) -> str:
        """The report in a few lines of plain text, for the command line."""

        def errors(e: Mapping[str, float]) -> str:
            return (f"rmse {e['rmse']:.4g}, relative rmse (log mu) {e['relative_rmse']:.4g}, "
                    f"max abs {e['max_abs_error']:.4g}")

        def estimates(values: Mapping[str, Mapping[str, float]], units: Mapping[str, str]) -> list[str]:
            return [f"  {n} = {v['value']:.6g} +/- {v['std']:.2g} [{units[n]}]" for n, v in values.items()]

        physics_units = {n: p.unit for n, p in physics.PARAMETERS.items()}
        lines = [f"{self.n_points} measurements, {self.folds}-fold cross-validation",
                 f"declared model, default parameters (in-sample): {errors(self.error_default)}"]
        if self.fitted_declared:
            lines.append("fitted declared parameters (before):")
            lines += estimates(self.fitted_declared, physics_units)
        lines.append(f"before (held out): {errors(self.error_before)}")
        effect = self.missing_effect
        if effect is None:
            lines.append("missing effect: none")
        else:
            lines.append(f"missing effect: {effect['name']} ({effect['title']}) driven by "
                         f"{', '.join(effect['drivers'])}")
            lines.append(f"  {effect['formula']}")
            lines += estimates({n: {"value": effect["parameters"][n], "std": effect["parameter_std"][n]}
                                for n in effect["parameters"]}, effect["parameter_units"])
            if self.fitted_parameters:
                lines.append("declared parameters of the calibrated model:")
                lines += estimates(self.fitted_parameters, physics_units)
        lines.append(f"after (held out, nested CV: the search redone within each fold): "
                     f"{errors(self.error_after)}")
        if effect is not None:
            lines.append(f"after on the folds that chose the effect (optimistic): "
                         f"{errors(self.error_after_selection)}")
        lines.append(f"stability: {self.effect_stability['summary']}")
        lines.append(f"GP discrepancy baseline (held out): {errors(self.discrepancy_gp['errors'])}")
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


def _unit(name: str) -> str:
    spec = physics.PARAMETERS.get(name)
    return f" [{spec.unit}]" if spec is not None else ""


def _residual_png(panels: list[tuple[str, np.ndarray]], series: list[tuple[str, np.ndarray]],
                  title: str) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = min(3, len(panels))
    rows = -(-len(panels) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.4 * rows), squeeze=False,
                             sharey=True, constrained_layout=True)
    for ax, (driver, x) in zip(axes.flat, panels, strict=False):
        for label, residual in series:
            ax.scatter(x, residual, s=8, alpha=0.6, label=label)
        ax.axhline(0.0, color="0.3", lw=0.8)
        ax.set_xlabel(f"{driver}{_unit(driver)}")
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel("log(mu_measured / mu_model),\nheld out [-]")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    plt.close(fig)
    return buffer.getvalue()


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
    ValueError
        Starting with the offending field (``data``, ``folds`` or ``fit_parameters``).
    """
    if dataset.n_points < MIN_ROWS:
        raise ValueError(f"data must have at least {MIN_ROWS} rows; got {dataset.n_points}")
    if not 2 <= folds <= dataset.n_points // 2:
        raise ValueError(f"folds must be in [2, {dataset.n_points // 2}] (half the rows); got {folds}")
    check_fit_parameters(dataset, fit_parameters)


def calibrate(data, fit_parameters: Sequence[str] = (), fixed: Mapping[str, Any] | None = None,
              folds: int = 5, seed: int = 0, gp_max_train: int = 300, make_plots: bool = True,
              progress: Callable[[float], None] | None = None,
              convention: str = physics.DEFAULT_CONVENTION, z_threshold: float = 3.0) -> CalibrationReport:
    """Calibrate the declared model on measurements, find and add the missing effect, report.

    Parameters
    ----------
    data : Dataset, str, bytes or sequence of mapping
        Measurements: a checked :class:`Dataset`, CSV text, or JSON-like rows.
    fit_parameters : sequence of str
        Declared physics parameters to fit, e.g. ``["mu_pivot", "adhesion_energy_J_m2"]``.
    fixed : mapping, optional
        Physics parameters fixed for every row (not with a ``Dataset``).
    folds : int
        Number of cross-validation folds, in [2, n_points]. [1]
    seed : int
        Seed of the folds (outer and nested inner ones) and of the GP's subset.
    gp_max_train : int
        Training rows per fold of the GP discrepancy at most. [1]
    make_plots : bool
        Whether to draw the residual plots.
    progress : callable, optional
        Called with the fraction done, 0..1, never decreasing (stages in :data:`PROGRESS_STAGES`).
    convention : str
        See :data:`physics.CONVENTIONS`.
    z_threshold : float
        Minimum paired z of a candidate's held-out improvement (see :func:`calibrate.discover.discover`). [1]

    Returns
    -------
    CalibrationReport
        ``error_after`` comes from nested cross-validation (the search repeated within every
        training fold, costing about ``folds`` more searches); ``error_after_selection`` is the
        chosen effect's optimistic same-fold figure.

    Raises
    ------
    calibrate.data.DataError
        For bad rows, cells or columns (every one listed).
    ValueError
        For fewer than :data:`MIN_ROWS` rows, bad ``folds`` or ``fit_parameters``.
    """
    report = progress or (lambda fraction: None)
    if convention not in physics.CONVENTIONS:
        raise ValueError(f"convention must be one of {', '.join(physics.CONVENTIONS)}; got {convention!r}")
    dataset = _as_dataset(data, fixed)
    check_request(dataset, fit_parameters, folds)
    report(0.0)
    ends = list(PROGRESS_STAGES.values())

    def stage(i: int) -> Callable[[float], None]:
        start = 0.0 if i == 0 else ends[i - 1]
        return lambda f: report(start + (ends[i] - start) * min(max(f, 0.0), 1.0))

    error_default = prediction_errors(predict_mu(dataset, {}, convention=convention), dataset.mu_measured)
    baseline = cross_validate_baseline(dataset, fit_parameters, folds, seed, convention)
    stage(0)(1.0)
    discovery: Discovery = discover(dataset, fit_parameters, folds, seed, z_threshold, baseline=baseline,
                                    progress=stage(1), convention=convention)
    stage(1)(1.0)
    nested = nested_cross_validate(dataset, fit_parameters, baseline, seed, z_threshold, progress=stage(2),
                                   convention=convention)
    stage(2)(1.0)
    gp = gp_discrepancy(dataset, baseline, gp_max_train, seed, progress=stage(3))
    stage(3)(1.0)
    declared = baseline.full_fit
    error_before = prediction_errors(baseline.oof_mu, dataset.mu_measured)
    error_after = prediction_errors(nested.oof_mu, dataset.mu_measured)

    chosen = discovery.chosen
    stability = nested.stability(None if chosen is None else chosen.choice)
    if chosen is None:
        final, error_after_selection, missing = declared, error_before, None
        effect_json = None
    else:
        choice = chosen.choice
        final = fit(dataset, fit_parameters, choice, start=declared.declared, convention=convention)
        error_after_selection = prediction_errors(chosen.oof_mu, dataset.mu_measured)
        spec = choice.effect
        missing = {
            "name": spec.name,
            "title": spec.title,
            "drivers": list(choice.drivers),
            "formula": spec.formula,
            "parameters": dict(final.effect_parameters),
            "parameter_std": dict(final.effect_std),
            "parameter_units": {p.name: p.unit for p in spec.parameters},
            "constants": dict(choice.constants),
            "reference": spec.reference,
        }
        effect_json = {"name": spec.name, "drivers": list(choice.drivers),
                       "parameters": dict(final.effect_parameters), "constants": dict(choice.constants)}
    model = CalibratedModel(dict(final.declared), dict(dataset.fixed), effect_json, convention)

    plots: dict[str, bytes] = {}
    if make_plots:
        before = np.log(dataset.mu_measured / baseline.oof_mu)
        after = np.log(dataset.mu_measured / nested.oof_mu)
        columns = dataset.columns()
        if chosen is None:
            varying = [(n, np.asarray(v, dtype=float)) for n, v in columns.items()
                       if np.unique(v).size > 1][:9]
            if varying:
                series = [("declared model, fitted", before)]
                if np.any(after != before):
                    series.append(("after (nested CV)", after))
                plots["residual"] = _residual_png(varying, series,
                                                  "Residual of the fitted declared model: nothing added")
        else:
            driver = chosen.choice.drivers[0]
            panel = [(driver, np.asarray(columns[driver], dtype=float))]
            plots["residual_before"] = _residual_png(panel, [("before", before)],
                                                     f"Before: fitted declared model against {driver}")
            plots["residual_after"] = _residual_png(panel, [("before", before), ("after (nested CV)", after)],
                                                    f"After: + {chosen.choice.name} against {driver}")
    report(1.0)
    return CalibrationReport(
        n_points=dataset.n_points,
        fit_parameters=list(declared.declared),
        error_default=error_default,
        fitted_declared=_values(declared.declared, declared.declared_std),
        fitted_parameters=_values(final.declared, final.declared_std),
        error_before=error_before,
        error_after=error_after,
        error_after_selection=error_after_selection,
        effect_stability=stability,
        missing_effect=missing,
        discrepancy_gp=gp,
        candidates=[discovery.baseline_score.summary()] + [c.summary() for c in discovery.candidates],
        decision=discovery.reason,
        folds=folds,
        model=model,
        plots=plots,
    )

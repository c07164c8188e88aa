"""Which measurements to take next on the friction model: :mod:`calibrate.design` on a calibration.

:func:`next_experiments` proposes runs for a calibrated model (:class:`calibrate.CalibratedModel`),
:func:`first_experiments` for the declared physics before any calibration (its declared parameters
only). Both build a candidate set of the lab's ``space`` (:func:`candidate_points`: a grid of every
continuous column's ends and middle levels with every allowed value and integer ball count, plus a
scrambled Sobol' set), hand the model to :func:`calibrate.design.plan` through
:class:`CalibratedResponse` (the response is log μ, the parameters the fitted values, the
information of the data taken the inverse of their covariance) and say what the runs are expected to
do in friction units.

Two functions are the points where the calibration's scatter model and its rival laws plug in:

* :meth:`CalibratedResponse.scatter_sd`: the standard deviation of one measurement of log μ at each run.
* :func:`rival_models`: the models the data could not tell apart from the calibrated one (told apart by
  ``discriminate``, hedged by ``predict``), rebuilt from the report's selection steps: named candidates
  that passed a step's test (in the chosen term's place; for ``predict`` half of it, and one generic form
  in place of a generic term), and the stopping step's best named one at half its threshold (added).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.physics.effects import EFFECTS
from microbearing.physics.spans import read_span

from .candidates import Term, candidate_terms
from .credibility import implausible
from .data import Dataset
from .design import GOALS, Design, DesignError, plan
from .design import check_identifiable as design_check
from .domain import outside_law_domains, outside_physical_ranges
from .fit import Z95, fit
from .model import CalibratedModel
from .plan_plot import plan_png
from .reported import ReportedWidth, columns_after, promise
from .shape_hedges import curvature_widths, shape_widths
from .spaces import MAX_CANDIDATES, candidate_points, check_space, read_space, space_points

__all__ = [
    "CalibratedResponse",
    "ExperimentPlan",
    "ExperimentRequest",
    "MAX_CANDIDATES",
    "MAX_RIVALS",
    "candidate_points",
    "check_identifiable",
    "check_request",
    "read_space",
    "first_experiments",
    "held_out_scale",
    "next_experiments",
    "physics_model",
    "plan_png",
    "rival_models",
    "space_points",
]

#: Rival models a discrimination design tells apart from the calibrated one at most. [1]
MAX_RIVALS = 3
# Points of the envelope at most. [1]
_ENVELOPE_POINTS = 512
# Points of the envelope added to the candidates of a predict design at most. [1]
_ENVELOPE_CANDIDATES = 128
# Relative step of the finite-difference sensitivities of log μ (as CalibratedModel.predict). [1]
_GRADIENT_STEP = 1e-6
# The stopping step's best candidate is a rival when its z reaches this share of the threshold. [1]
_NEAR_THRESHOLD = 0.5
_GENERIC_RIVALS = 1  # generic rivals a predict design hedges at most, beside the named ones [1]


# ------------------------------------------------------------------------------------------------ model
@dataclass
class CalibratedResponse:
    """A calibrated model as a :class:`calibrate.design.DesignModel`: log μ and its sensitivities.

    Attributes
    ----------
    model : CalibratedModel
        The model (a physics model before calibration: fitted declared values, no terms).
    fixed : mapping
        Inputs and conditions held at one value in every run (in their units).
    """

    model: CalibratedModel
    fixed: Mapping[str, Any]

    @property
    def parameter_names(self) -> list[str]:
        names = list(self.model.fitted)
        for term, _ in self.model.terms:
            names += [f"{term.label}: {n}" for n in term.parameter_names]
        return names

    @property
    def parameter_units(self) -> list[str]:
        units = [physics.PARAMETERS[n].unit for n in self.model.fitted]
        for term, _ in self.model.terms:
            units += [term.units[n] for n in term.parameter_names]
        return units

    @property
    def parameter_values(self) -> list[float]:
        return [*map(float, self.model.fitted.values()), *(x for _, v in self.model.terms for x in v)]

    def points(self, points: Mapping[str, Any]) -> dict[str, np.ndarray]:
        count = max((np.size(v) for v in points.values()), default=1)
        return {**{k: np.full(count, v) for k, v in self.fixed.items()},
                **{k: np.asarray(v) for k, v in points.items()}}

    def _log_mu(self, points, flat: Sequence[float]) -> np.ndarray:
        n_fitted = len(self.model.fitted)
        fitted = dict(zip(self.model.fitted, flat[:n_fitted], strict=True))
        rest, values = list(flat[n_fitted:]), []
        for _, v in self.model.terms:
            values.append(rest[: len(v)])
            rest = rest[len(v):]
        return np.log(self.model.mu_at(points, fitted, values))

    def response(self, points):
        """log μ at the points [1] (with the GP discrepancy's mean when the model has one)."""
        full = self.points(points)
        self.model.check_columns(full)
        return np.log(self.model(full))

    def sensitivities(self, points):
        """d log μ / d parameter at the points, by forward differences (parameters in their units)."""
        full = self.points(points)
        flat = self.parameter_values
        base = self._log_mu(full, flat)
        gradient = np.zeros((base.size, len(flat)))
        with np.errstate(all="ignore"):
            for j, x in enumerate(flat):
                step = _GRADIENT_STEP * (abs(x) if x != 0 else 1.0)
                shifted = list(flat)
                shifted[j] = x + step
                try:
                    gradient[:, j] = ((self._log_mu(full, shifted) - base) / step).ravel()
                except ValueError:  # the step left the input's range: move the other way
                    shifted[j] = x - step
                    gradient[:, j] = ((base - self._log_mu(full, shifted)) / step).ravel()
        return np.where(np.isfinite(gradient), gradient, 0.0)

    def scatter_sd(self, points):
        """Standard deviation of one measurement of log μ at each point [1].

        The calibration's scatter model where it depends on an input (:mod:`calibrate.scatter`: a step or
        a log-linear trend in one column, e.g. 10 % below 20 mm/s and 1.5 % above), so that runs where
        measurements scatter less weigh more; else its one held-out scatter, ``noise_std_log``.
        """
        count = max((np.size(v) for v in points.values()), default=1)
        scatter = getattr(self.model, "scatter", None)
        if scatter is not None and scatter.kind != "constant":
            columns = self.model.columns_at(points)
            if scatter.column in columns:
                return np.broadcast_to(np.asarray(scatter.std_log(columns, (count,)), dtype=float),
                                       (count,)).copy()
        return np.full(count, float(self.model.noise_std_log))

    def prior_information(self):
        """The information of the data taken on the parameters: the inverse of their covariance (None
        for a model without one: a first design)."""
        if self.model.covariance is None:
            return None
        covariance = np.asarray(self.model.covariance, dtype=float)
        covariance = np.where(np.isfinite(covariance), covariance, 0.0)
        return np.linalg.pinv((covariance + covariance.T) / 2, hermitian=True)


# ----------------------------------------------------------------------------------------------- rivals
def _find_term(dataset: Dataset, chosen: Sequence[Term], label: str) -> Term | None:
    return next((t for t in candidate_terms(dataset, chosen) if t.label == label), None)


def _named(candidate: Mapping[str, Any]) -> bool:
    effect = EFFECTS.get(candidate.get("effect") or "")
    return candidate.get("kind") == "drift" or (effect is not None and not effect.generic)


def rival_terms(report: Mapping[str, Any], dataset: Dataset, terms: Sequence[Term], near: bool = False
                ) -> list[tuple[str, list[Term]]]:
    """The terms of each rival of a calibration, read from its selection steps (see the module).

    Parameters
    ----------
    report : mapping
        The calibration report (:meth:`calibrate.CalibrationReport.to_dict`): ``steps``.
    dataset : Dataset
        The calibration's data (the candidate terms are rebuilt on it).
    terms : sequence of Term
        The calibrated model's terms, in order.
    near : bool
        Also a law, generic too, in place of a chosen term that reached half the step's threshold (not
        the whole): a law new runs may well choose instead, which a ``predict`` design hedges against.

    Returns
    -------
    list of (str, list of Term)
        Each rival's description and its terms, best scored first.
    """
    found: list[tuple[float, str, list[Term]]] = []
    for k, step in enumerate(report.get("steps", [])):
        prefix = list(terms[:k])
        for candidate in step.get("candidates", [])[1:]:
            if (not candidate.get("joint_refit") or not (near or _named(candidate))
                    or candidate["label"] == step["added"]):
                continue
            z = float(candidate["z_vs_declared"])
            needed = float(step["z_needed"]) * (_NEAR_THRESHOLD if near else 1.0)
            if step["added"] is not None and z > needed and k < len(terms):
                term = _find_term(dataset, prefix, candidate["label"])
                if term is not None:
                    found.append((candidate["score"], f"{candidate['label']} in place of {terms[k].label}",
                                  [*prefix, term, *terms[k + 1:]]))
            elif step["added"] is None and z >= _NEAR_THRESHOLD * float(step["z_needed"]):
                term = _find_term(dataset, list(terms), candidate["label"])
                if term is not None:
                    found.append((candidate["score"], f"{candidate['label']} added (z = {z:.2f}, threshold "
                                  f"{float(step['z_needed']):.2f})", [*terms, term]))
    found.sort(key=lambda item: item[0])
    unique: dict[str, tuple[str, list[Term]]] = {}
    for _, label, rival in found:
        unique.setdefault(label, (label, rival))
    return list(unique.values())


def _generic_rival(terms: Sequence[Term], own: set[str]) -> bool:
    """Whether a term the model lacks is a generic fallback, not a mechanism."""
    return any(t.generic for t in terms if t.label not in own)


def rival_models(report: Mapping[str, Any], dataset: Dataset, model: CalibratedModel,
                 max_rivals: int = MAX_RIVALS, near: bool = False) -> list[tuple[str, CalibratedModel]]:
    """The models a calibration could not tell apart from its own, each refitted on its data.

    Where the calibration's rivals within one standard error plug in; today from
    :func:`rival_terms`.

    Parameters
    ----------
    report : mapping
        The calibration report (``steps``, ``fit_parameters``).
    dataset : Dataset
        The calibration's data.
    model : CalibratedModel
        The calibrated model (its convention, scatter and conditions carry over).
    max_rivals : int
        Named rivals at most, best scored first; with ``near`` :data:`_GENERIC_RIVALS` more in place of a
        generic term of the model. [1]
    near : bool
        Also the laws that came near to replacing a chosen term, generic ones too (:func:`rival_terms`).

    Returns
    -------
    list of (str, CalibratedModel)
    """
    rivals = []
    fit_parameters = list(report.get("fit_parameters", model.fitted))
    # the small-sample and tail factor the model's interval applies to its scatter
    factor = model.interval_noise_std_log() / float(model.noise_std_log) if model.noise_std_log else 1.0
    own = {t.label for t, _ in model.terms}
    columns = {**dataset.inputs(), **dataset.conditions}
    found = rival_terms(report, dataset, [t for t, _ in model.terms], near)
    named = [(label, terms) for label, terms in found if not _generic_rival(terms, own)]
    # a generic law in place of a generic term (a fallback's form: the runs decide it, the others kept)
    generic = [(label, terms) for label, terms in found if _generic_rival(terms, own)
               and any(t.generic for t, _ in model.terms if t.label not in {u.label for u in terms})]
    for label, terms in [*named[:max_rivals], *generic[:_GENERIC_RIVALS]]:
        result = fit(dataset, fit_parameters, terms, start=model.fitted, convention=model.convention)
        # a law whose refit leaves its physical range is no rival (the search refuses it likewise)
        if any(implausible(t, v, columns, result.declared, dataset.fixed)
               for t, v in zip(terms, result.term_values, strict=True) if t.label not in own):
            continue
        # A rival's scatter is its own fit's (a term the model lacks inflates the model's scatter, and a
        # recalibration that adds it measures less), with the model's factor; its data cloud the model's.
        noise = _residual_scatter(result) * factor
        rivals.append((label, CalibratedModel.from_fit(result, dataset, model.convention, noise,
                                                       cloud=model.cloud)))
    return rivals


def held_out_scale(report: Mapping[str, Any], dataset: Dataset, model: CalibratedModel) -> float:
    """How much the scatter a calibration measures held out exceeds an in-sample residual scatter on these
    data [1]: the calibrated model's held-out scatter over its own terms' in-sample residual (with its
    degrees of freedom), at least 1. A rival's scatter (:func:`rival_models`) is in-sample, and a
    recalibration that adds its term measures it held out: compared as they are, a rival that fits as
    well looks better by the refit's share of a held-out residual (temperature lab 5 of
    ``bench/plans_promise.py``: a rival's 0.0317 in-sample against 0.0342-0.0351 held out after the
    runs)."""
    if not model.noise_std_log:
        return 1.0
    fit_parameters = list(report.get("fit_parameters", model.fitted))
    terms = [t for t, _ in model.terms]
    try:
        own = _residual_scatter(fit(dataset, fit_parameters, terms, start=model.fitted,
                                    start_terms=[list(v) for _, v in model.terms],
                                    convention=model.convention))
    except (ValueError, np.linalg.LinAlgError):
        return 1.0
    return max(1.0, float(model.noise_std_log) / own) if own > 0 else 1.0


def _residual_scatter(result) -> float:
    """RMS of a fit's log residual with its degrees of freedom (n - p) [1]."""
    residual = np.asarray(result.residual, dtype=float)
    dof = max(residual.size - len(result.values), 1)
    return float(np.sqrt(np.sum(np.square(residual)) / dof))


# ------------------------------------------------------------------------------------------------- plan
@dataclass(frozen=True)
class ExperimentRequest:
    """What a proposal (:func:`next_experiments`, :func:`first_experiments`) is asked for.

    Attributes
    ----------
    space : mapping
        What the lab can set, per column (physics inputs such as ``balls``, ``load_N`` [N],
        ``speed_m_s`` [m/s], and the calibration's condition columns in its units): a range
        ``[low, high]``, ``{"low", "high", "spacing"}`` or ``{"values": [...]}`` (:func:`space_points`).
    runs : int
        Runs to propose, 1-500. [1]
    goal : str
        ``discriminate`` (tell the rivals apart), ``parameters`` (D-optimal) or ``predict`` (I-optimal
        over ``envelope``).
    envelope : mapping, optional
        Where the model will be used, like ``space`` (``predict``; with another goal, the intervals
        there are reported too).
    fixed : mapping, optional
        Inputs and conditions at one value in every run.
    planned : sequence of mapping, optional
        Runs already planned (one value per column of ``space``).
    seed : int
        Seed of the candidate set.
    shown : mapping, optional
        Column -> the :class:`physics.columns.Reading` of the key the request sent it under: the runs'
        domain warnings word those columns under that key, in its unit (``RH [%] = 80``).
    """

    space: Mapping[str, Any]
    runs: int
    goal: str
    envelope: Mapping[str, Any] | None = None
    fixed: Mapping[str, Any] | None = None
    planned: Sequence[Mapping[str, float]] | None = None
    seed: int = 0
    shown: Mapping[str, Any] | None = None


@dataclass(frozen=True)
class ExperimentPlan:
    """Proposed runs and what they are expected to do, JSON-ready through :meth:`to_dict`."""

    design: Design
    runs: list[dict[str, Any]]
    expected: dict[str, Any]
    plot: dict[str, Any]
    warnings: list[str]
    #: The goal asked for when it differs from the design's (``discriminate`` with no rival: explored).
    asked: str | None = None

    def to_dict(self) -> dict[str, Any]:
        d = self.design
        return {
            "goal": self.asked or d.goal,
            "runs": self.runs,
            "criterion": d.criterion,
            "efficiency_lower_bound": d.efficiency_lower_bound,
            "continuous_efficiency_lower_bound": d.continuous_efficiency_lower_bound,
            "rounding_efficiency": d.rounding_efficiency,
            "support_points": int(np.count_nonzero(d.counts)),
            "solver": d.solver,
            **self.expected,
            "plot": self.plot,
            "warnings": list(self.warnings),
        }


def _half_width(mu: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Half the width of the 95 % log-normal interval μ exp(±1.96 σ) [1]."""
    return mu * np.sinh(Z95 * sigma)


def _tidy(value) -> float:
    """A set-point as a lab would type it: 12 significant digits (0.9, not 0.8999999999999999)."""
    return float(f"{float(value):.12g}")


def _runs(response: CalibratedResponse, candidates, design: Design,
          shown: Mapping[str, Any] | None = None) -> tuple[list[dict], dict, list[str]]:
    rows = design.runs
    chosen = {k: np.asarray(v)[rows] for k, v in candidates.items()}
    full = response.points(chosen)
    prediction = response.model.predict(full, shown=shown)
    inside = (None if prediction.in_domain is None
              else np.broadcast_to(prediction.in_domain, (rows.size,)))
    runs = []
    for i in range(rows.size):
        inputs = {k: v[i] for k, v in full.items() if k in physics.PARAMETERS}
        conditions = {k: _tidy(v[i]) for k, v in full.items() if k not in physics.PARAMETERS}
        run = {"balls": int(inputs.pop("balls")), "load_N": _tidy(inputs.pop("load_N")),
               "speed_m_s": _tidy(inputs.pop("speed_m_s")),
               "inputs": {k: (bool(v) if physics.PARAMETERS[k].kind == "bool" else _tidy(v))
                          for k, v in inputs.items()},
               "conditions": conditions, "mu": float(np.ravel(prediction.mu)[i]),
               "in_domain": None if inside is None else bool(inside[i])}
        if prediction.mu_lower is not None:
            run["mu_lower"] = float(np.ravel(prediction.mu_lower)[i])
            run["mu_upper"] = float(np.ravel(prediction.mu_upper)[i])
        runs.append(run)
    return runs, chosen, list(prediction.warnings)


def _expected(goal: str, response: CalibratedResponse, design: Design, chosen, envelope,
              rivals: Sequence[tuple[str, CalibratedModel]], reported: Sequence[ReportedWidth] = (),
              held_out_scale: float = 1.0, data: Mapping[str, np.ndarray] | None = None) -> dict[str, Any]:
    names = response.parameter_names
    information_after = design.information_after
    covariance_after = np.linalg.pinv(information_after, hermitian=True)
    prior = response.prior_information()
    now = None if prior is None else np.linalg.pinv(prior, hermitian=True)
    out: dict[str, Any] = {}
    out["parameters"] = [
        {"name": n, "value": v, "unit": u,
         "std_now": None if now is None else float(np.sqrt(max(now[j, j], 0.0))),
         "std_after": float(np.sqrt(max(covariance_after[j, j], 0.0)))}
        for j, (n, v, u) in enumerate(zip(names, response.parameter_values, response.parameter_units,
                                          strict=True))]
    if envelope is not None:
        full = response.points(envelope)
        mu = np.ravel(response.model(full))
        g = response.sensitivities(envelope)
        noise = np.square(response.scatter_sd(envelope))
        var_after = np.einsum("ij,jk,ik->i", g, covariance_after, g)
        after = _half_width(mu, np.sqrt(var_after + noise))
        mean_after = _half_width(mu, np.sqrt(var_after))
        entry: dict[str, Any] = {"points": int(mu.size),
                                 "half_width_after": {"mean": float(after.mean()), "max": float(after.max())},
                                 "mean_half_width_after": {"mean": float(mean_after.mean()),
                                                           "max": float(mean_after.max())}}
        if now is not None:
            var_now = np.einsum("ij,jk,ik->i", g, now, g)
            before = _half_width(mu, np.sqrt(var_now + noise))
            mean_before = _half_width(mu, np.sqrt(var_now))
            entry["half_width_now"] = {"mean": float(before.mean()), "max": float(before.max())}
            entry["mean_half_width_now"] = {"mean": float(mean_before.mean()),
                                            "max": float(mean_before.max())}
        if reported:  # the interval as the service reports it, widened off the data
            entry.update(promise(reported, design.counts, held_out_scale,
                                 columns_after(data, response.points(chosen)),
                                 {t.label for t, _ in response.model.terms}))
        out["envelope"] = entry
    if rivals:
        full = response.points(chosen)
        mu_reference = np.ravel(response.model(full))
        listed = []
        for (label, rival), separation in zip(rivals, design.rival_separation, strict=True):
            mu_rival = np.ravel(rival(full))
            listed.append({"label": label, "terms": [t.label for t, _ in rival.terms],
                           "expected_chi2_separation": float(separation),
                           "max_relative_difference": float(np.max(np.abs(mu_rival / mu_reference - 1.0))),
                           "mu_at_runs": mu_rival.tolist()})
        out["rivals"] = listed
        out["mu_reference_at_runs"] = mu_reference.tolist()
    return out


def _span(spec: Any) -> tuple[float, float]:
    span = read_span("space", spec, number=False)
    return span.low, span.high


def _curve_points(response: CalibratedResponse, runs_columns, space, x_name: str):
    low, high = _span(space[x_name])
    x = np.linspace(low, high, 60)
    if x_name == "balls":
        x = np.unique(np.round(x))
    others = {n: np.full(x.size, np.median(runs_columns[n])) for n in space if n != x_name}
    if "balls" in others:
        others["balls"] = np.round(others["balls"])
    return x, others, response.points({**others, x_name: x})


def _plot_data(response: CalibratedResponse, runs_columns, data: Mapping[str, np.ndarray] | None,
               space: Mapping[str, Any], rivals, max_data: int = 2000) -> dict[str, Any]:
    """What the plot draws: two columns of the space, the runs and the data taken on them, and (with
    rivals) each model's μ along the first, the others at the runs' medians.

    With rivals the first column is the one along which they differ most from the calibrated model;
    otherwise columns are ranked by the share of their range the runs span plus twice the share of the
    runs outside the data's range (runs beyond the data are what a reader must see)."""
    def spread(name: str) -> float:
        low, high = _span(space[name])
        values = np.asarray(runs_columns[name], dtype=float)
        return float(np.ptp(values) / (high - low)) if high > low else 0.0

    def beyond(name: str) -> float:
        """Share of the runs outside the data's range on the column by more than a tenth of the space's
        range (where the runs teach most)."""
        if data is None or name not in data or not len(data[name]):
            return 0.0
        values = np.asarray(runs_columns[name], dtype=float)
        column = np.asarray(data[name], dtype=float)
        low, high = _span(space[name])
        margin = 0.1 * (high - low)
        return float(np.mean((values < column.min() - margin) | (values > column.max() + margin)))

    varying = sorted(space, key=lambda n: -(spread(n) + 2.0 * beyond(n)))
    if rivals:
        def difference(name: str) -> float:
            _x, _others, points = _curve_points(response, runs_columns, space, name)
            reference = np.log(np.ravel(response.model(points)))
            return max(float(np.ptp(np.log(np.ravel(rival(points))) - reference)) for _, rival in rivals)

        # The columns that drive the terms where the rivals differ from the model come first.
        own = {t.label: t for t, _ in response.model.terms}
        drivers: list[str] = []
        for _, rival in rivals:
            theirs = {t.label: t for t, _ in rival.terms}
            for label in set(own) ^ set(theirs):
                drivers += [d for d in (own.get(label) or theirs[label]).drivers if d in space]
        first = (max(set(drivers), key=lambda d: (drivers.count(d), difference(d))) if drivers
                 else max(space, key=difference))
        varying = [first, *[n for n in varying if n != first]]
    axes = varying[:2]
    plot: dict[str, Any] = {"axes": axes, "runs": {a: np.asarray(runs_columns[a], dtype=float).tolist()
                                                    for a in axes}}
    if data is not None:
        count = len(next(iter(data.values()))) if data else 0
        take = np.linspace(0, count - 1, min(count, max_data)).astype(int) if count else np.zeros(0, int)
        plot["data"] = {a: np.asarray(data[a], dtype=float)[take].tolist() for a in axes if a in data}
    else:
        plot["data"] = {}
    curves = []
    if rivals and axes:
        x, others, points = _curve_points(response, runs_columns, space, axes[0])
        curves.append({"label": "calibrated model", "x": x.tolist(),
                       "mu": np.ravel(response.model(points)).tolist()})
        for label, rival in rivals:
            curves.append({"label": label, "x": x.tolist(), "mu": np.ravel(rival(points)).tolist()})
        plot["others"] = {n: float(v[0]) for n, v in others.items()}
    plot["curves"] = curves
    return plot


def _with_envelope(candidates: Mapping[str, np.ndarray], envelope: Mapping[str, np.ndarray],
                   space: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The candidates with the envelope's points the space allows (at most :data:`_ENVELOPE_CANDIDATES`,
    evenly taken): for ``predict``, measuring where the model will be used is a run to consider."""
    inside = np.ones(len(next(iter(envelope.values()))), dtype=bool)
    for name, spec in space.items():
        values = np.asarray(envelope[name], dtype=float)
        if "values" in spec:
            inside &= np.isin(values, np.asarray(spec["values"], dtype=float))
        else:
            inside &= (values >= float(spec["low"])) & (values <= float(spec["high"]))
            if name == "balls":
                inside &= values == np.round(values)
    index = np.flatnonzero(inside)
    index = index[np.unique(np.linspace(0, index.size - 1, min(index.size, _ENVELOPE_CANDIDATES)).astype(int))
                  ] if index.size else index
    return {k: np.concatenate([np.asarray(v, dtype=float), np.asarray(envelope[k], dtype=float)[index]])
            for k, v in candidates.items()}


def _envelope_points(envelope: Mapping[str, Any], seed: int) -> dict[str, np.ndarray]:
    """The points of an envelope (ranges and sets, :func:`read_space`) a proposal is judged over."""
    return space_points(envelope, _ENVELOPE_POINTS, seed, sobol_points=64)


def _propose(response: CalibratedResponse, request: ExperimentRequest, rivals, data,
             progress, held_out_scale: float = 1.0) -> ExperimentPlan:
    report = progress or (lambda fraction: None)
    space, runs, goal, seed = request.space, request.runs, request.goal, request.seed
    envelope_space, planned = request.envelope, request.planned
    candidates = candidate_points(space, seed)
    envelope = None
    if envelope_space is not None:  # its columns the space's (check_request)
        envelope = _envelope_points(envelope_space, seed)
    for field_name, points in (("space", candidates), ("envelope", envelope)):
        if points is None:
            continue
        with np.errstate(all="ignore"):
            mu = np.ravel(response.model(response.points(points)))
        bad = ~(np.isfinite(mu) & (mu > 0))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            example = ", ".join(f"{n} = {float(np.asarray(v)[k]):.6g}" for n, v in points.items())
            raise ValueError(f"{field_name}: the model has no finite mu at {int(bad.sum())} of its points "
                             f"(e.g. {example}); narrow the ranges")
    planned_columns = _planned_columns(space, planned, response.fixed)
    report(0.2)
    rival_responses = [CalibratedResponse(m, response.fixed) for _, m in rivals]
    # A calibrated model's interval widens off the data (the data cloud, the ranges of its inputs): the
    # runs for predict are chosen by that interval, as the service will report it after them.
    reported, hedges = None, []
    if envelope is not None and response.model.covariance is not None and response.model.domain is not None:
        if goal == "predict":
            candidates = _with_envelope(candidates, envelope, space)
        reported = ReportedWidth(response, candidates, envelope, planned_columns)
        # A recalibration may add a rival's term: the runs hedge against it (its interval counts too).
        hedges = [ReportedWidth(r, candidates, envelope, planned_columns) for r in rival_responses
                  if r.model.covariance is not None] if goal == "predict" else []
        if goal == "predict":  # and the laws of an input the envelope extrapolates (calibrate.shape_hedges)
            hedges += shape_widths(response, data, envelope, candidates, planned_columns)
    exchange = None
    if reported is not None and goal == "predict":
        bends = curvature_widths(response, data, envelope, candidates, planned_columns)  # search only

        def exchange(start: np.ndarray) -> np.ndarray:
            return reported.search(start, [*hedges, *bends])
    design = plan(response, candidates, runs, goal, envelope=envelope, rivals=rival_responses,
                  planned=planned_columns, exchange=exchange)
    report(0.8)
    rows, chosen, warnings = _runs(response, candidates, design, request.shown)
    expected = _expected(goal, response, design, chosen, envelope, rivals if goal == "discriminate" else [],
                         [reported, *hedges] if reported is not None else [], held_out_scale, data)
    plot = _plot_data(response, chosen, data, space, rivals if goal == "discriminate" else [])
    if envelope_space is not None:  # where the model will be used, on the plot's axes
        plot["envelope"] = {a: list(_span(envelope_space[a])) for a in plot["axes"] if a in envelope_space}
    if design.efficiency_lower_bound < 0.5:
        warnings.append(f"the runs are proven only {design.efficiency_lower_bound:.2f} efficient: few runs "
                        f"cannot carry the continuous design; more runs round better")
    report(1.0)
    return ExperimentPlan(design, rows, expected, plot, warnings)


def _planned_columns(space: Mapping[str, Any], planned: Sequence[Mapping[str, float]] | None,
                     fixed: Mapping[str, Any]) -> dict[str, np.ndarray] | None:
    """The planned runs as columns: every column any run gives, a fixed one too (a run planned at another
    groove angle), the fixed value where a run leaves it out."""
    if not planned:
        return None
    given = dict.fromkeys([*space, *(k for row in planned for k in row)])
    return {k: np.array([row.get(k, fixed.get(k)) for row in planned], dtype=float) for k in given}


def check_identifiable(response: CalibratedResponse, request: ExperimentRequest) -> None:
    """Refuse a request whose space cannot identify the parameters before its job runs: the proposal's
    refusal (:func:`calibrate.design.check_identifiable`) over the candidates it draws, the envelope's
    points among them for ``predict``, with the data taken and the planned runs. ``discriminate`` tells
    models apart and needs no identification.

    Raises
    ------
    DesignError
        Starting with ``space``: the combination of parameters no run over the space moves.
    """
    if request.goal == "discriminate":
        return
    request = _read_spaces(request)
    candidates = candidate_points(request.space, request.seed)
    envelope_space = request.envelope if request.goal == "predict" else None
    if envelope_space is not None and set(request.space) <= set(envelope_space):
        candidates = _with_envelope(candidates, _envelope_points(envelope_space, request.seed), request.space)
    try:
        design_check(response, candidates, _planned_columns(request.space, request.planned, response.fixed))
    except DesignError as exc:
        raise DesignError(f"space: {exc}") from None


def _read_spaces(request: ExperimentRequest) -> ExperimentRequest:
    """The request with its space and envelope as ranges and sets (:func:`read_space`)."""
    envelope = None if request.envelope is None else read_space(request.envelope, "envelope")
    return replace(request, space=read_space(request.space), envelope=envelope)


def next_experiments(
    model: CalibratedModel,
    request: ExperimentRequest,
    rivals: Sequence[tuple[str, CalibratedModel]] = (),
    data: Mapping[str, np.ndarray] | None = None,
    progress: Callable[[float], None] | None = None,
    held_out_scale: float = 1.0,
) -> ExperimentPlan:
    """The next ``request.runs`` measurements for a calibrated model, with an optimality bound.

    Parameters
    ----------
    model : CalibratedModel
        The calibrated model (a model with covariance and scatter).
    request : ExperimentRequest
        The space, the runs, the goal, and the envelope, fixed values, planned runs and seed.
    rivals : sequence of (str, CalibratedModel)
        ``discriminate``: the rivals (:func:`rival_models`). ``predict``: optional; the runs then shrink
        the envelope variance of the model and of the rivals together (model-robust).
    data : mapping of str to numpy.ndarray, optional
        The data taken (columns), drawn under the proposed runs.
    progress : callable, optional
        Fraction done, 0..1.
    held_out_scale : float
        The rivals' scatter as a recalibration would measure it, over their own in-sample scatter
        (:func:`held_out_scale`); read by the promise, ``reported_half_width_after``. [1]

    Returns
    -------
    ExperimentPlan

    Raises
    ------
    calibrate.design.DesignError
        For an unknown goal, a missing envelope or rivals, or parameters the space cannot identify.
    ValueError
        For an invalid space, fixed value or planned run (naming the field).
    """
    goal = request.goal
    if goal not in GOALS:
        raise DesignError(f"goal must be one of {', '.join(GOALS)}; got {goal!r}")
    if model.covariance is None or model.noise_std_log is None:
        raise DesignError("the calibrated model has no covariance or scatter (stored before version 2)")
    response = check_request(model, request.space, request.fixed, request.envelope, request.planned)
    if goal == "discriminate" and not rivals:
        return _explore(response, request, data, progress)
    return _propose(response, _read_spaces(request), list(rivals) if goal != "parameters" else [], data,
                    progress, held_out_scale)


def _explore(response: CalibratedResponse, request: ExperimentRequest, data, progress) -> ExperimentPlan:
    """``discriminate`` with no rival: runs where the data say least, the reason stated.

    Nothing is left to tell apart, so the runs shrink the 95 % interval the service reports over the
    envelope, or the whole space without one (a ``predict`` design by :class:`ReportedWidth`): it is
    widest beyond the data's ranges and away from its rows, where an effect the data have not seen would
    show."""
    where = "the envelope" if request.envelope is not None else "the whole space"
    explored = replace(request, goal="predict", envelope=request.envelope or request.space)
    proposal = _propose(response, _read_spaces(explored), [], data, progress)
    reason = (f"the calibration left no rival model within reach of the one it chose, so there is nothing "
              f"to tell apart: the runs explore where the data say least instead, shrinking the 95 % "
              f"interval the service reports over {where} (widest beyond the data's ranges and away from "
              f"its rows, where an effect the data have not seen would show)")
    return replace(proposal, warnings=[reason, *proposal.warnings], asked="discriminate")


def check_request(model: CalibratedModel, space: Mapping[str, Any], fixed: Mapping[str, Any] | None = None,
                  envelope: Mapping[str, Any] | None = None,
                  planned: Sequence[Mapping[str, float]] | None = None) -> CalibratedResponse:
    """Check a proposal's request against a model before any work; the model as a design model.

    Raises
    ------
    ValueError
        Starting with the offending field (``space.<column>``, ``envelope.<column>``,
        ``fixed.<name>``, ``planned.<i>``): an unknown column, a bad range or value, a value outside
        the domain of a term's law, a column the model reads that is neither in the space nor fixed.
    """
    check_space(space, model.conditions)
    if envelope is not None:
        check_space(envelope, model.conditions, "envelope")
        missing = [n for n in space if n not in envelope]
        if missing:  # the proposal's refusal, at submit
            raise ValueError(f"envelope: give the columns of the space too ({', '.join(missing)})")
    for name in (n for n in model.fitted if n in space):  # a setting cannot be what the runs measure
        raise ValueError(f"space.{name}: {name} is a fitted parameter, which the runs measure; a space sets "
                         f"what the runs vary: leave it out of the space or of fit_parameters")
    fixed = dict(fixed or {})
    for name, value in fixed.items():
        if name in space:
            raise ValueError(f"fixed.{name}: also a column of the space; give it in one of them")
        if name in physics.PARAMETERS:
            try:
                physics.validate(name, value)
            except ValueError as exc:
                raise ValueError(f"fixed.{name}: {exc}") from None
        elif name not in model.conditions:
            raise ValueError(f"fixed.{name}: not a physics input nor a condition column of the data "
                             f"({', '.join(model.conditions) or 'none'})")
    planned_runs = [(f"planned.{i}", run) for i, run in enumerate(planned or [])]
    for field, run in planned_runs:
        for name in run:
            if name not in physics.PARAMETERS and name not in model.conditions:
                raise ValueError(f"{field}.{name}: not a physics input nor a condition column of the data "
                                 f"({', '.join(model.conditions) or 'none'})")
    for field, columns in (("space", space), ("envelope", envelope or {}), ("fixed", fixed), *planned_runs):
        # a value outside its quantity's physical range is said so first, as at every door
        outside = {**outside_law_domains(model.terms, columns),
                   **outside_physical_ranges(model.conditions, columns)}
        for name, detail in outside.items():
            raise ValueError(f"{field}.{name}: {detail}")
    required = ["balls", "load_N", "speed_m_s", *model.required_columns]
    missing = [n for n in required if n not in space and n not in fixed
               and not (n in physics.PARAMETERS and (n in model.fixed or physics.PARAMETERS[n].default
                                                     is not None))]
    if missing:
        raise ValueError(f"space: give {', '.join(missing)} in the space or in fixed (the model reads them)")
    given = dict.fromkeys(k for row in planned or [] for k in row)  # every column of any planned run
    for i, row in enumerate(planned or []):
        absent = [n for n in space if n not in row]
        if absent:
            raise ValueError(f"planned.{i}: give {', '.join(absent)} (the columns of the space)")
        # a column some runs give and this one does not: its value is the fixed one, or none is known
        unknown = [n for n in given if n not in row and n not in fixed]
        if unknown:
            raise ValueError(f"planned.{i}: give {unknown[0]} (other planned runs do, and it is not fixed)")
    return CalibratedResponse(model, fixed)


def physics_model(fit_parameters: Sequence[str], noise_std_log: float,
                  guess: Mapping[str, float] | None = None, fixed: Mapping[str, Any] | None = None,
                  convention: str = physics.DEFAULT_CONVENTION) -> tuple[CalibratedModel, dict[str, Any]]:
    """The declared physics before a calibration as a model of :func:`first_experiments`: the fitted
    parameters at ``guess`` (or ``fixed``, or the defaults), no covariance, the expected scatter; and the
    fixed values that are not fitted.

    Raises
    ------
    ValueError
        Naming ``fit_parameters``, ``guess.<name>`` or ``noise_std_log``.
    """
    if not (np.isfinite(noise_std_log) and noise_std_log > 0):
        raise ValueError(f"noise_std_log: must be positive; got {noise_std_log}")
    guess, fixed = dict(guess or {}), dict(fixed or {})
    fitted = {}
    for name in fit_parameters:
        spec = physics.PARAMETERS.get(name)
        if spec is None or spec.kind == "bool":
            raise ValueError(f"fit_parameters: {name!r} is not a numeric physics parameter")
        value = guess.get(name, fixed.get(name, spec.default))
        if value is None:
            raise ValueError(f"guess.{name}: give a value (the parameter has no default)")
        try:
            fitted[name] = float(physics.validate(name, value))
        except ValueError as exc:
            raise ValueError(f"guess.{name}: {exc}") from None
    model = CalibratedModel(fitted, {}, [], convention, None, float(noise_std_log), None, [])
    return model, {k: v for k, v in fixed.items() if k not in fitted}


def first_experiments(
    fit_parameters: Sequence[str],
    request: ExperimentRequest,
    noise_std_log: float = 0.05,
    guess: Mapping[str, float] | None = None,
    convention: str = physics.DEFAULT_CONVENTION,
    progress: Callable[[float], None] | None = None,
) -> ExperimentPlan:
    """A first design on the declared physics, before any calibration: its declared parameters only.

    Parameters
    ----------
    fit_parameters : sequence of str
        Declared physics parameters the data will fit (e.g. ``mu_pivot`` [1]).
    request : ExperimentRequest
        As :func:`next_experiments`; its goal ``parameters`` or ``predict`` (nothing to discriminate
        before a calibration).
    noise_std_log : float
        Expected standard deviation of one measurement of log μ (the relative scatter) [1].
    guess : mapping, optional
        Values of the fitted parameters the sensitivities are taken at (default: the physics'
        defaults), in their units.
    convention : str
        See :data:`physics.CONVENTIONS`.
    progress : callable, optional
        Fraction done, 0..1.

    Returns
    -------
    ExperimentPlan
        Without figures "now" (no data taken): the parameters' standard deviations and the intervals
        after the runs.
    """
    if request.goal not in ("parameters", "predict"):
        raise DesignError(f"goal must be parameters or predict before a calibration; got {request.goal!r}")
    if not fit_parameters:
        raise DesignError("fit_parameters: name at least one declared parameter to design for")
    model, fixed = physics_model(fit_parameters, noise_std_log, guess, request.fixed, convention)
    response = check_request(model, request.space, fixed, request.envelope, request.planned)
    return _propose(response, _read_spaces(request), [], None, progress)

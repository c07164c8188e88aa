"""A calibrated model as plain JSON data, rebuilt into a callable with intervals and a domain (no pickle).

The model is the physics of :func:`physics.evaluate` with the values fixed by
the calibration request, the fitted declared parameters and the terms chosen by
forward selection (:mod:`calibrate.candidates`), with what
:meth:`CalibratedModel.predict` needs to say how sure it is and where it holds:
the covariance of the fitted values, the scatter of a new measurement around
the model, and the range of every column of the data it was fitted on. When
nested cross-validation showed that a Gaussian process on what the terms leave
predicts better (:func:`calibrate.discrepancy.residual_gp`), the model also
holds that GP (:class:`GPCorrection`): its mean corrects log μ and its
predictive variance widens the interval where the data say little. Terms that
fit the data about as well as the chosen ones (:mod:`calibrate.rivals`) are
kept as :class:`RivalModel`: the interval is the envelope of the model's and
theirs, so that it holds their disagreement where they part ways off the data.

Models stored before version 2 (one effect, no covariance, no domain) still
load; they answer μ without an interval and without a domain check.

Three optional parts make the interval follow the data (models without them answer as before):

* ``groups`` (:class:`calibrate.groups.GroupEffect`): a factor column's random effect. A point naming
  a known group (its label under the factor's name) is moved by that group's level; a new label, or
  none, carries the spread between groups in its interval.
* ``scatter`` (:class:`calibrate.scatter.ScatterModel`): the measurement scatter as a function of one
  input, in place of the one ``noise_std_log`` everywhere.
* ``cloud`` (:class:`calibrate.domain.DataCloud`): the joint cloud of the data's rows. A point far
  from every row is out of the domain even inside every column's range, and its interval's log
  half-width grows with the distance.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np
from scipy import special

from microbearing import physics

from .candidates import FrozenBase, Term, mu_of, term_from_json
from .data import Dataset, factor_label
from .domain import EXTRAPOLATION_SHARE, DataCloud, extrapolation_allowance, extrapolation_bound, range_slack
from .fit import Z95, FitResult
from .gp_correction import GPCorrection
from .groups import GroupEffect
from .rival_model import RivalModel, covariance_from_json
from .scatter import ScatterModel

__all__ = ["CalibratedModel", "GPCorrection", "Prediction", "RivalModel", "FORMAT_VERSION"]

FORMAT_VERSION = 2
# Relative step of the finite-difference gradient of log mu in the fitted values.
_GRADIENT_STEP = 1e-6


@dataclass(frozen=True)
class Prediction:
    """μ of a calibrated model with its 95 % interval and domain check, per point.

    Attributes
    ----------
    mu : numpy.ndarray
        Predicted μ. [1]
    mu_lower, mu_upper : numpy.ndarray or None
        Bounds of the 95 % prediction interval of a new measurement [1]: parameter uncertainty,
        what the terms leave unexplained and the measurement noise (None for a model stored before
        intervals existed).
    in_domain : numpy.ndarray or None
        Whether each point lies within the ranges of the data the model was fitted on (None for a
        model stored before domains existed).
    warnings : list of str
        One sentence per column outside the domain, naming the column, the value(s) and the range.
    """

    mu: np.ndarray
    mu_lower: np.ndarray | None
    mu_upper: np.ndarray | None
    in_domain: np.ndarray | None
    warnings: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class SharedPieces:
    """What a calibrated model's interval and its rivals' share at the points (they have the same
    discrepancy, scatter and data cloud): the discrepancy's shift of log μ and its variance, the scatter's
    variance and the data cloud's distance ratio [1]."""

    shift: np.ndarray
    discrepancy_variance: np.ndarray
    noise_variance: np.ndarray
    cloud_score: np.ndarray


@dataclass(frozen=True)
class CalibratedModel:
    """Physics + fitted declared parameters + terms, with covariance, scatter and domain.

    Attributes
    ----------
    fitted : dict of str to float
        Fitted physics parameters, in their units.
    fixed : dict
        Physics parameters fixed by the calibration request.
    terms : list of tuple of (Term, list of float)
        The chosen terms with their fitted values, in order.
    convention : str
        See :data:`physics.CONVENTIONS`.
    covariance : numpy.ndarray or None
        Covariance of the fitted values: declared (in ``fitted`` order), then each term's.
    noise_std_log : float or None
        Standard deviation of log μ of a new measurement around the model (held-out scatter by
        nested cross-validation, robust). [1]
    domain : dict of str to list of float, or None
        ``[min, max]`` of every column of the data (physics inputs in their units, conditions in the
        data's units).
    conditions : list of str
        Condition columns of the data (the only non-physics keys a point may give).
    discrepancy : GPCorrection or None
        Gaussian-process discrepancy of log μ on what the terms leave, when nested cross-validation
        showed that it helps; its columns are then needed by a prediction.
    rivals : list of RivalModel
        Models whose terms fit the data about as well (:mod:`calibrate.rivals`): the 95 % interval is
        the envelope of this model's and theirs, so that it holds their disagreement off the data.
    clock : dict of str to str
        Condition columns read from ISO 8601 times (hours since the start) and that start, ISO 8601: a
        point may give such a column as an ISO 8601 time too (:func:`calibrate.data.hours_since`).
    groups : list of GroupEffect
        Random effects of the data's factor columns (group labels); a point may name its group.
    scatter : ScatterModel or None
        Standard deviation of log μ of a new measurement as a function of an input [1] (None: the
        one ``noise_std_log`` everywhere).
    cloud : DataCloud or None
        The data's rows in scaled inputs, for the joint-cloud domain check.
    domain_rows : int or None
        Rows of the data the domain was taken from [1]; with it, a column's range is widened by twice
        the mean spacing of its values, 2 (max - min) / (rows - 1), at each end (a new point drawn like
        the data lies beyond a sample's extreme with chance 1/(rows + 1) per column and end: a box of the
        exact extremes flags several per cent of ordinary points when there are several columns).
    headers : dict of str to str
        The upload's header of each column it sent in another unit than the column's name says
        (:attr:`Dataset.headers`): a key at prediction that states no unit is judged against it.
    edge_trends : dict of str to list of float
        Per physics input, the departure the held-out residuals and generic terms trend to beyond each end
        of its range (:func:`calibrate.domain.edge_trends`, log μ): the extrapolation allowance grows by it.
    """

    fitted: dict[str, float] = field(default_factory=dict)
    fixed: dict[str, Any] = field(default_factory=dict)
    terms: list[tuple[Term, list[float]]] = field(default_factory=list)
    convention: str = physics.DEFAULT_CONVENTION
    covariance: np.ndarray | None = field(default=None, repr=False)
    noise_std_log: float | None = None
    domain: dict[str, list[float]] | None = None
    conditions: list[str] = field(default_factory=list)
    discrepancy: GPCorrection | None = field(default=None, repr=False)
    groups: list[GroupEffect] = field(default_factory=list)
    scatter: ScatterModel | None = None
    cloud: DataCloud | None = field(default=None, repr=False)
    domain_rows: int | None = None
    rivals: list[RivalModel] = field(default_factory=list, repr=False)
    clock: dict[str, str] = field(default_factory=dict)
    headers: dict[str, str] = field(default_factory=dict)
    edge_trends: dict[str, list[float]] = field(default_factory=dict)
    #: Relative step of the finite-difference gradient of log μ in each fitted value (the interval's
    #: parameter share; absolute for a value of 0), for callers that bound the interval. [1]
    gradient_step: ClassVar[float] = _GRADIENT_STEP

    @property
    def factors(self) -> list[str]:
        """Factor columns (group labels) a point may give."""
        return [g.factor for g in self.groups]

    def split_factors(self, points: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
        """The points' numeric columns, and their factor columns (group labels)."""
        labels = {k: v for k, v in points.items() if k in self.factors}
        return {k: v for k, v in points.items() if k not in labels}, labels

    @property
    def required_columns(self) -> list[str]:
        """Columns a point must give besides the physics inputs: the terms' drivers, the rivals' and
        the GP discrepancy's columns that are not physics inputs, but those of :attr:`column_defaults`."""
        terms = [term for term, _ in self.terms] + [term for rival in self.rivals for term, _ in rival.terms]
        needed = [d for term in terms for d in term.drivers if d not in physics.PARAMETERS]
        if self.discrepancy is not None:
            needed += [f for f in self.discrepancy.features if f not in physics.PARAMETERS]
        defaults = self.column_defaults
        return [name for name in dict.fromkeys(needed) if name not in defaults]

    @property
    def column_defaults(self) -> dict[str, float]:
        """Condition columns the model's terms read only through terms of the measurement system (an
        instrument's drift or step over an order or time column; :attr:`physics.effects.Effect.identity_at`),
        each with the value a point that does not give it takes: where every such term is the identity (the
        least of their values: a step is the identity anywhere before its place), so the answer is the
        bearing's μ, the reading as it is taken to be true; its rivals are asked there too (their reading
        at the same place of the session). A column the discrepancy reads is required."""
        features = set(self.discrepancy.features) if self.discrepancy is not None else set()
        values: dict[str, list[float | None]] = {}
        for term, _ in self.terms:
            for name in term.drivers:
                if name not in physics.PARAMETERS:
                    main = name == term.drivers[0]
                    values.setdefault(name, []).append(term.identity_value if main else None)
        return {name: min(v) for name, v in values.items()
                if name not in features and all(x is not None for x in v)}

    def _given_or_default(self, points: Mapping[str, Any]) -> dict[str, Any]:
        """The points with each of :attr:`column_defaults` they do not give."""
        return {**{k: v for k, v in self.column_defaults.items() if k not in points}, **points}

    def check_columns(self, names) -> None:
        """Raise ValueError naming a column that is neither a physics input nor a known condition,
        or a condition the terms need that is missing."""
        if self.domain is not None:
            unknown = [n for n in names if n not in physics.PARAMETERS and n not in self.conditions
                       and n not in self.factors]
            if unknown:
                known = ", ".join(self.conditions) or "none"
                raise ValueError(
                    f"unknown condition column(s) {', '.join(map(repr, unknown))}; the calibration "
                    f"data had the conditions: {known}"
                )
        missing = [c for c in self.required_columns if c not in names]
        if missing:
            users = [t.label for t, _ in self.terms if set(t.drivers) & set(missing)]
            users += [f"the rival {r.label}" for r in self.rivals
                      if any(set(t.drivers) & set(missing) for t, _ in r.terms)]
            if self.discrepancy is not None and set(self.discrepancy.features) & set(missing):
                users.append("the Gaussian-process discrepancy")
            raise ValueError(
                f"the calibrated model needs condition column(s) {', '.join(missing)} (used by "
                f"{', '.join(users)})"
            )

    def _physics_inputs(self, points: Mapping[str, Any], fitted: Mapping[str, float]) -> dict[str, Any]:
        """The physics' inputs at columnar points: the fixed values, ``fitted``, and the points' physics
        columns over both."""
        return {**self.fixed, **fitted, **{k: v for k, v in points.items() if k in physics.PARAMETERS}}

    def _mu(self, points: Mapping[str, Any], fitted: Mapping[str, float], values,
            physics_mu: np.ndarray | None = None) -> np.ndarray:
        """μ with these fitted and term values; ``physics_mu``: the physics' μ at them, already known (a
        model without drift terms, whose terms' values do not move the physics)."""
        inputs = self._physics_inputs(points, fitted)
        conditions = {k: np.asarray(v, dtype=float) for k, v in points.items() if k not in physics.PARAMETERS}
        base = None if physics_mu is None else FrozenBase(physics_mu, {})
        return mu_of(inputs, conditions, [t for t, _ in self.terms], values, base=base,
                     convention=self.convention)

    def _physics_mu(self, points: Mapping[str, Any]) -> np.ndarray | None:
        """The physics' μ at the fitted values, as :meth:`_mu` computes it, when no drift term moves it
        (else None). [1]"""
        if any(t.kind == "drift" for t, _ in self.terms):
            return None
        inputs = self._physics_inputs(points, self.fitted)
        return physics.evaluate(convention=self.convention, outputs=["mu"],
                                **{k: np.asarray(v) for k, v in inputs.items()}).mu

    def _discrepancy(self, points: Mapping[str, Any], shape) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of the GP discrepancy of log μ (zeros without one) [1]."""
        if self.discrepancy is None:
            return np.zeros(shape), np.zeros(shape)
        return self.discrepancy(self.discrepancy_columns(points), shape)

    def discrepancy_columns(self, points: Mapping[str, Any]) -> dict[str, Any]:
        """The columns the GP discrepancy reads at points: theirs over the fitted, fixed and default ones."""
        return {**physics.defaults(), **self.fixed, **self.fitted, **points}

    def __call__(self, points: Mapping[str, Any]) -> np.ndarray:
        """μ at columnar points.

        Parameters
        ----------
        points : mapping of str to array_like
            Physics inputs by name (broadcasting like :func:`physics.evaluate`; values given here
            override fixed and fitted ones) and the condition columns the terms read.

        Returns
        -------
        numpy.ndarray
            μ. [1]

        Raises
        ------
        ValueError
            For invalid physics inputs, an unknown condition column or a missing one the terms need.
        """
        self.check_columns(points)
        points, labels = self.split_factors(self._given_or_default(points))
        mu = np.asarray(self._mu(points, self.fitted, [v for _, v in self.terms]), dtype=float)
        mu = mu * np.exp(self._discrepancy(points, mu.shape)[0])
        if self.groups:
            mu = mu * np.exp(self._group_terms(points, labels, mu.shape)[0])
        return mu

    def predict(self, points: Mapping[str, Any], level: float = 0.95, *, domain: bool = True,
                shown: Mapping[str, Any] | None = None) -> Prediction:
        """μ with its prediction interval and a domain check, at columnar points.

        This is the calibrated model's one prediction interface: arrays of inputs and conditions
        in, μ, its bounds and where it holds out.

        Parameters
        ----------
        points : mapping of str to array_like
            As for :meth:`__call__`.
        level : float
            Probability that a new measurement falls inside [mu_lower, mu_upper]; 0.95 by default. [1]
        domain : bool, default True
            False: no domain check (``in_domain`` None, no warnings; μ and the bounds are the same), for
            callers that read the interval only, many times over (a robust design's worst case).
        shown : mapping, optional
            Column -> the :class:`physics.columns.Reading` of the key a request sent it under: the
            domain warnings word that column's values and range under that key, in its unit
            (:meth:`domain_check`).

        Returns
        -------
        Prediction
            μ [1], the bounds [1] (log-normal: μ exp(± z σ), σ² the parameter variance of log μ at
            the point, plus the GP discrepancy's predictive variance there when the model has one,
            plus the group's (a known group's level, or the spread between groups for a new one),
            plus the scatter² at the point (:attr:`scatter`, else :attr:`noise_std_log`²); σ times the
            distance ratio beyond the data cloud where it exceeds 1), the domain flag per point and
            the warnings.

        Raises
        ------
        ValueError
            As :meth:`__call__`.
        """
        self.check_columns(points)
        said = self._default_words(points)
        points, labels = self.split_factors(self._unmoved(self._given_or_default(points)))
        values = [list(v) for _, v in self.terms]
        # The physics evaluated once serves μ and every step of a term's value in the gradient below (the
        # same numbers as evaluating it again; only a fitted value's step moves it)
        physics_mu = self._physics_mu(points)
        mu = np.asarray(self._mu(points, self.fitted, values, physics_mu), dtype=float)
        shift, discrepancy_variance = self._discrepancy(points, mu.shape)
        # the labels too: a label no group of the data has is predicted as a new group, and said so
        in_domain, warnings = self.domain_check({**points, **labels}, shown) if domain else (None, [])
        if domain:
            warnings = [*warnings, *said]
        if self.covariance is None or self.noise_std_log is None:
            return Prediction(mu * np.exp(shift), None, None, in_domain, warnings)
        # What the model and its rivals share (the same discrepancy, scatter and data cloud), computed once.
        shared = SharedPieces(shift, discrepancy_variance, self._noise_variance(points, mu.shape, level),
                              self._cloud_score(points, mu.shape))
        mu, lower, upper = self._interval(points, labels, level, mu, physics_mu, shared,
                                          self.extrapolation_ratio(points, mu.shape))
        for record, rival in zip(self.rivals, self.rival_models(), strict=True):
            # The envelope of the rivals' intervals (calibrate.rivals); a rival that cannot predict a
            # point (a driver outside its law) leaves it to the others, said.
            try:
                _, other_lower, other_upper = rival.rival_interval(points, labels, level, shared)
            except ValueError as exc:
                warnings = [*warnings, f"the rival {record.label} cannot predict here ({exc}): the interval "
                                       f"holds the model and its other rivals only"]
                continue
            ok = np.isfinite(other_lower) & np.isfinite(other_upper) & (other_lower > 0)
            if not np.all(ok):
                warnings = [*warnings, f"the rival {record.label} cannot predict at {int(np.sum(~ok))} of "
                                       f"{ok.size} point(s) (outside its law's domain there): the interval "
                                       f"there holds the model and its other rivals only"]
            lower = np.where(ok, np.minimum(lower, other_lower), lower)
            upper = np.where(ok, np.maximum(upper, other_upper), upper)
        return Prediction(mu, lower, upper, in_domain, warnings)

    def _default_words(self, points: Mapping[str, Any]) -> list[str]:
        """What a prediction that leaves out a column of :attr:`column_defaults` answers."""
        users = {name: [t.label for t, _ in self.terms if name in t.drivers] for name in self.column_defaults}
        return [f"{name} not given: the bearing's mu without the measurement system's "
                f"{', '.join(users[name]) or 'terms'} (the reading as at {name} {value:.6g}, taken as true)"
                for name, value in self.column_defaults.items() if name not in points]

    def _unmoved(self, points: Mapping[str, Any]) -> dict[str, Any]:
        """The points without a fitted parameter given at its fitted value, one number (an optimization's
        design carries the model's values): that value's uncertainty stays in the interval, and a rival
        keeps its own value."""
        return {name: value for name, value in points.items() if not (
            name in self.fitted and np.ndim(value) == 0 and float(value) == self.fitted[name])}

    def rival_interval(self, points: Mapping[str, Any], labels: Mapping[str, Any], level: float,
                       shared: SharedPieces) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """μ and the interval of this model as a rival of the model whose ``shared`` pieces it reads, at
        points that model has read (:meth:`predict` calls it on each of :meth:`rival_models`: the same
        discrepancy, scatter and cloud, no column box, so no extrapolation allowance of its own); what
        would change with its own fitted values is computed anew."""
        self.check_columns({**points, **labels})
        points = self._unmoved(points)
        physics_mu = self._physics_mu(points)
        values = [list(v) for _, v in self.terms]
        mu = np.asarray(self._mu(points, self.fitted, values, physics_mu), dtype=float)
        varying_scatter = self.scatter is not None and self.scatter.kind != "constant"
        reads_fitted = set(self.fitted).intersection(
            (*(self.discrepancy.features if self.discrepancy is not None else ()),
             *(self.cloud.columns if self.cloud is not None else ()),
             *((self.scatter.column,) if varying_scatter else ())))
        if reads_fitted or mu.shape != shared.shift.shape:
            shift, discrepancy_variance = self._discrepancy(points, mu.shape)
            shared = SharedPieces(shift, discrepancy_variance, self._noise_variance(points, mu.shape, level),
                                  self._cloud_score(points, mu.shape))
        if self.covariance is None or self.noise_std_log is None:
            return mu * np.exp(shared.shift), np.full(mu.shape, np.nan), np.full(mu.shape, np.nan)
        return self._interval(points, labels, level, mu, physics_mu, shared,
                              self.extrapolation_ratio(points, mu.shape))

    def _interval(self, points: Mapping[str, Any], labels: Mapping[str, Any], level: float, mu: np.ndarray,
                  physics_mu: np.ndarray | None, shared: SharedPieces, extrapolation: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """μ with the discrepancy's and groups' shifts, and the interval's bounds [1], from μ of the terms
        at the points and the pieces this model shares with its rivals."""
        gradient, stepped = self._gradient(points, mu, physics_mu)
        variance = np.einsum("i...,ij,j...->...", gradient, self.covariance, gradient)
        group_shift, group_variance = self._group_terms(points, labels, mu.shape, level, (mu, stepped))
        # Beyond the data cloud or a physics input's range the share no fitted value explains (the scatter
        # and the discrepancy) widens (:meth:`cloud_ratio`): the departure no term holds, in its unit; the
        # fitted values' and groups' share is propagated by the model's form at the point, counted once.
        wide = self.widening(np.maximum(shared.cloud_score, extrapolation))
        sigma = np.sqrt(np.clip(variance, 0.0, None) + group_variance
                        + (shared.discrepancy_variance + shared.noise_variance) * wide * wide)
        z = float(-special.ndtri((1.0 - level) / 2.0))  # stats.norm.isf's number, without its overhead
        mu = mu * np.exp(shared.shift + group_shift)
        return mu, mu * np.exp(-z * sigma), mu * np.exp(z * sigma)

    def _gradient(self, points: Mapping[str, Any], mu: np.ndarray, physics_mu: np.ndarray | None
                  ) -> tuple[np.ndarray, dict[str, tuple[float, np.ndarray]]]:
        """The finite-difference gradient of log μ in the fitted and term values at the points [1], and μ
        after each fitted value's step (its step and μ there; for the groups' sensitivities)."""
        values = [list(v) for _, v in self.terms]
        names = list(self.fitted)
        flat = list(self.fitted.values()) + [x for v in values for x in v]
        gradient = np.zeros((len(flat), *mu.shape))
        stepped: dict[str, tuple[float, np.ndarray]] = {}
        with np.errstate(all="ignore"):
            for j, x in enumerate(flat):
                step = _GRADIENT_STEP * (abs(x) if x != 0 else 1.0)
                shifted = list(flat)
                shifted[j] = x + step
                fitted = dict(zip(self.fitted, shifted[: len(self.fitted)], strict=True))
                rest, term_values = shifted[len(self.fitted) :], []
                for v in values:
                    term_values.append(rest[: len(v)])
                    rest = rest[len(v) :]
                try:
                    known = physics_mu if j >= len(self.fitted) else None
                    moved = self._mu(points, fitted, term_values, known)
                    if j < len(names):
                        stepped[names[j]] = (step, moved)
                    gradient[j] = (np.log(moved) - np.log(mu)) / step
                except ValueError:  # the step left a physics input's range: that direction is not varied
                    gradient[j] = 0.0
        return np.where(np.isfinite(gradient), gradient, 0.0), stepped

    def _cloud_score(self, points: Mapping[str, Any], shape) -> np.ndarray:
        """The data cloud's distance ratio at the points [1] (zeros without a cloud): :meth:`cloud_ratio`
        without the extrapolation allowance, which a rival (no column box) does not add."""
        if self.cloud is None:
            return np.zeros(shape)
        points = {k: v for k, v in points.items() if k not in self.factors}
        columns = {k: v for k, v in self.columns_at(points).items() if k in points or k in physics.PARAMETERS}
        return self.cloud.score(columns, shape)[0]

    def rival_models(self) -> list[CalibratedModel]:
        """Each rival as a model of its own (same fixed values, scatter, groups, data cloud and
        discrepancy; no column box)."""
        return [replace(self, fitted=dict(r.fitted), terms=list(r.terms), covariance=r.covariance,
                        domain=None, rivals=[]) for r in self.rivals]

    def columns_at(self, points: Mapping[str, Any]) -> dict[str, Any]:
        """Every column a point has: its own, else the model's fixed, fitted or default value (what the
        model reads there: physics inputs in SI units, conditions in the data's units)."""
        return {**physics.defaults(), **self.fixed, **self.fitted, **self._given_or_default(points)}

    def mu_at(self, points: Mapping[str, Any], fitted: Mapping[str, float],
              term_values: Sequence[Sequence[float]]) -> np.ndarray:
        """μ of the physics with the given fitted values and its terms with the given values [1], without
        the discrepancy and the groups: the model as a function of its parameters, for sensitivities.

        Parameters
        ----------
        points : mapping of str to array_like
            Physics inputs and condition columns (no factor columns).
        fitted : mapping of str to float
            A value for each of :attr:`fitted`, in its unit.
        term_values : sequence of sequence of float
            The values of each term of :attr:`terms`, in order.
        """
        return self._mu(self._given_or_default(points), fitted, term_values)

    def _noise_variance(self, points: Mapping[str, Any], shape, level: float = 0.95) -> np.ndarray:
        """Variance of log μ of a new measurement around the model at the points [1]: the scatter model's,
        with the allowance for the degrees of freedom that inform it there (a step's side: its rows; a
        log-linear trend: the fit's uncertainty at the point; :meth:`ScatterModel.quantile_factor`), or
        ``noise_std_log``² (also where the scatter model's column is not given)."""
        if self.scatter is not None and self.scatter.kind != "constant":
            columns = self.columns_at(points)
            if self.scatter.column in columns:
                return np.square(self.scatter.std_log(columns, shape)
                                 * self.scatter.quantile_factor(columns, shape, level))
        # One spread everywhere: its small-sample allowance and heavy-tail factor (calibrate.tails).
        constant = self.scatter is not None and self.scatter.kind == "constant"
        factor = self.scatter.quantile_factor({}, shape, level) if constant else 1.0
        return np.square(float(self.noise_std_log or 0.0) * factor) * np.ones(shape)

    def _group_terms(self, points: Mapping[str, Any], labels: Mapping[str, Any], shape,
                     level: float = 0.95, known: tuple[np.ndarray, Mapping[str, tuple[float, np.ndarray]]]
                     | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Shift of log μ by the groups' levels and its variance at the points [1] (see :attr:`groups`);
        the sensitivity to a group's parameter is taken where the parameter acts, which may be a value
        the point gives. ``known``: μ at the points and μ after each fitted value's step (its step and μ,
        :meth:`_gradient`), which the sensitivity reads instead of evaluating them again."""
        shift, variance = np.zeros(shape), np.zeros(shape)
        for group in self.groups:
            if group.parameter == "mu" or group.parameter not in self.fitted:
                s = np.ones(shape)
            else:
                # d log mu / d log p at the points, by a finite difference of p where it acts: a point may
                # give p itself (an optimizer passes the model's fitted values as inputs).
                name = group.parameter
                value = np.asarray(points.get(name, self.fitted[name]), dtype=float)
                step = _GRADIENT_STEP * np.maximum(np.abs(value), 1e-12)
                values = [v for _, v in self.terms]
                with np.errstate(all="ignore"):
                    base = np.log(self._mu(points, self.fitted, values) if known is None else known[0])
                    if name in points:
                        moved = np.log(self._mu({**points, name: value + step}, self.fitted, values))
                    elif known is not None and name in known[1] and known[1][name][0] == float(step):
                        moved = np.log(known[1][name][1])
                    else:
                        moved = np.log(self._mu(points, {**self.fitted, name: value + step}, values))
                s = np.where(np.isfinite(moved - base), (moved - base) / step * value, 1.0)
            s = np.broadcast_to(s, shape)
            a, b, _ = group.shift(labels.get(group.factor), s, level)
            shift, variance = shift + a, variance + b
        return shift, variance

    def _label_warnings(self, points: Mapping[str, Any]) -> list[str]:
        """A sentence per factor column given labels that are not groups of the data (new groups)."""
        out = []
        for group in self.groups:
            if group.factor in points:
                labels = np.unique(np.vectorize(factor_label, otypes=[object])(
                    np.asarray(points[group.factor], dtype=object).ravel()))
                new = [str(x) for x in labels if x not in group.levels]
                if new:
                    shown = ", ".join(new[:3]) + (", ..." if len(new) > 3 else "")
                    out.append(f"{group.factor} = {shown} is not a group of the calibration data: predicted "
                               f"as a new group, whose interval carries the spread between groups")
        return out

    def cloud_ratio(self, points: Mapping[str, Any], shape=None) -> np.ndarray:
        """Distance ratio of each point from the data (> 1: outside, and the interval's scatter share is
        multiplied by it) [1]: the larger of the distance to the data cloud over the cloud's threshold
        and :meth:`extrapolation_ratio` (beyond the data's range in a physics input the point gives);
        zeros inside without a cloud. Physics columns a point does not give take the model's values."""
        points = {k: v for k, v in points.items() if k not in self.factors}
        if shape is None:
            shape = np.broadcast_shapes(*(np.shape(v) for v in points.values())) if points else ()
        ratio = self.extrapolation_ratio(points, shape)
        return ratio if self.cloud is None else np.maximum(self._cloud_score(points, shape), ratio)

    def extrapolation_inputs(self) -> dict[str, tuple[float, float]]:
        """The physics inputs the data varied (numeric columns of the domain whose values differ), each
        with its range [its unit]: the inputs :meth:`extrapolation_ratio` scores."""
        out = {}
        for name, (lo, hi) in (self.domain or {}).items():
            spec = physics.PARAMETERS.get(name)
            if spec is not None and spec.kind != "bool" and name not in self.factors and hi > lo:
                out[name] = (lo, hi)
        return out

    def extrapolation_ratio(self, points: Mapping[str, Any], shape=None) -> np.ndarray:
        """The extrapolation allowance at each point [1] (:func:`calibrate.domain.extrapolation_allowance`),
        largest over the physics inputs the point gives (:meth:`extrapolation_inputs`); 0 inside every
        range. Physics inputs the data did not vary and condition columns (which have rivals) are not
        scored."""
        points = {k: v for k, v in points.items() if k not in self.factors}
        if shape is None:
            shape = np.broadcast_shapes(*(np.shape(v) for v in points.values())) if points else ()
        return extrapolation_bound(self.extrapolation_inputs(), self.domain_rows, points, points, shape,
                                   trends=self._trend_ratios())

    def _trend_ratios(self) -> dict[str, list[float]]:
        """:attr:`edge_trends` in units of the 95 % half-width of the scatter (z x noise), the allowance's
        unit: beyond an end the interval's half-width grows by at least the departure there."""
        scale = Z95 * float(self.noise_std_log or 0.0)
        if not scale > 0:
            return {}
        # log mu values in the scatter's unit; the generic terms' rates (places 5 and 7) are per coordinate
        return {k: [x if i in (5, 7) else x / scale for i, x in enumerate(v)]
                for k, v in self.edge_trends.items()}

    def discrepancy_bound(self, low: Mapping[str, Any], high: Mapping[str, Any], shape
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bounds of the GP discrepancy over boxes of points (every column between its value in ``low`` and
        in ``high``, columnar, one box per entry): least and largest mean of log μ and largest variance [1]
        (:meth:`GPCorrection.bound`); zeros without one."""
        if self.discrepancy is None:
            return np.zeros(shape), np.zeros(shape), np.zeros(shape)
        return self.discrepancy.bound(self.discrepancy_columns(low), self.discrepancy_columns(high), shape)

    def discrepancy_least_variance(self, low: Mapping[str, Any], high: Mapping, shape) -> np.ndarray:
        """A lower bound of the GP discrepancy's latent variance over boxes of points (as
        :meth:`discrepancy_bound`) [1] (:meth:`GPCorrection.least_variance`); zeros without one."""
        if self.discrepancy is None:
            return np.zeros(shape)
        columns = [self.discrepancy_columns(points) for points in (low, high)]
        return self.discrepancy.least_variance(columns[0], columns[1], shape)

    def cloud_ratio_bound(self, low: Mapping[str, Any], high: Mapping[str, Any], shape,
                          lower: bool = False) -> np.ndarray:
        """An upper (``lower``: a lower) bound of :meth:`cloud_ratio` over boxes of points [1]: every point
        whose every column lies between its value in ``low`` and in ``high`` (columnar, one box per entry,
        both giving the same columns; :meth:`DataCloud.score_bound`, :meth:`DataCloud.score_lower_bound`,
        and the extrapolation allowance's exact range over the box)."""
        low = {k: v for k, v in low.items() if k not in self.factors}
        high = {k: v for k, v in high.items() if k not in self.factors}
        ratio = extrapolation_bound(self.extrapolation_inputs(), self.domain_rows, low, high, shape, lower,
                                    self._trend_ratios())
        if self.cloud is None:
            return ratio
        given = list(low)
        columns = [{k: v for k, v in self.columns_at({k: points[k] for k in given}).items()
                    if k in given or k in physics.PARAMETERS} for points in (low, high)]
        bound = self.cloud.score_lower_bound if lower else self.cloud.score_bound
        return np.maximum(bound(columns[0], columns[1], shape), ratio)

    def interval_noise_std_log(self, level: float = 0.95) -> float:
        """The noise of log μ the interval applies where the scatter is one spread: :attr:`noise_std_log`
        times the scatter's small-sample and tail factor at ``level`` [1]."""
        base = float(self.noise_std_log or 0.0)
        if self.scatter is not None and self.scatter.kind == "constant":
            return base * float(np.max(self.scatter.quantile_factor({}, (), level)))
        return base

    def widening(self, ratio: Any) -> np.ndarray:
        """Factor on the interval's scatter share (its noise's and discrepancy's standard deviation; the
        fitted values' and groups' share is not widened) at a distance ratio (:meth:`cloud_ratio`) [1]: the
        data cloud's rule (:meth:`calibrate.domain.DataCloud.widening`), ``max(ratio, 1)`` without a cloud."""
        if self.cloud is not None:
            return self.cloud.widening(ratio)
        return np.maximum(np.asarray(ratio, dtype=float), 1.0)

    def domain_check(self, points: Mapping[str, Any], shown: Mapping[str, Any] | None = None
                     ) -> tuple[np.ndarray | None, list[str]]:
        """Whether each point lies within the data's ranges, and a warning per column outside.

        A physics input that was not a data column is inside only at the value the calibration used
        (fixed, fitted or default). ``shown`` (column -> :class:`physics.columns.Reading` of the key a
        request sent it under) words a column's values and range under that key, in its unit (``RH [%]
        = 65 is outside the calibration data's range [20, 49.4]``); the others in the column's own.

        Returns
        -------
        tuple
            Boolean array broadcast like the points (None without a stored domain), list of str.
        """
        if self.domain is None:
            return None, []
        warnings = self._label_warnings(points)
        points = {k: v for k, v in points.items() if k not in self.factors}
        shape = np.broadcast_shapes(*(np.shape(v) for v in points.values())) if points else ()
        inside = np.ones(shape, dtype=bool)
        ratio = None  # the distance ratio the interval is widened by (cloud_ratio), computed once when needed
        for name, given in points.items():
            value = np.broadcast_to(np.asarray(given, dtype=float), shape)
            label, to_shown, unit = _as_shown(name, (shown or {}).get(name))
            if name in self.domain:
                lo, hi = self.domain[name]
                slack = float(range_slack(lo, hi, self.domain_rows))
                ok = (value >= lo - slack) & (value <= hi + slack)
                ends = sorted(to_shown(v) for v in (lo, hi))
                where = f"outside the calibration data's range [{ends[0]:.6g}, {ends[1]:.6g}]{unit}"
            elif name in physics.PARAMETERS:
                used = self.fitted.get(name, self.fixed.get(name, physics.PARAMETERS[name].default))
                if used is None:  # a required input the model never had a value for: nothing to compare
                    continue
                used = float(used)
                ok = np.isclose(value, used, rtol=1e-9, atol=0.0)
                where = f"not the value the calibration used, {to_shown(used):.6g}{unit}"
            else:
                continue
            if not np.all(ok):
                bad = value[~ok]
                values = ", ".join(f"{to_shown(x):.6g}" for x in np.unique(bad)[:3]) + (
                    ", ..." if np.unique(bad).size > 3 else ""
                )
                widened = ""
                if name in self.extrapolation_inputs():
                    # The factor the interval gets there: the larger of every input's allowance and the
                    # distance from the data cloud, which may exceed this input's allowance (a cloud that
                    # reads the input in its unit, 300 mm/s beyond data at 5-50 mm/s: 14.6 against 4.09).
                    ratio = self.cloud_ratio(points, shape) if ratio is None else ratio
                    applied = float(np.max(self.widening(np.broadcast_to(ratio, shape)[~ok])))
                    trend = self._trend_ratios().get(name)
                    factor = float(np.max(extrapolation_allowance(bad, lo, hi, self.domain_rows, trend)[0]))
                    share = 100 * EXTRAPOLATION_SHARE
                    rule = f"by one for every {share:.0f} % of the data's span beyond it" + (
                        ", and by the departure the data's residuals trend to at that end"
                        if trend and any(trend) else "")
                    why = (f"the extrapolation allowance: {rule}" if applied <= factor * (1 + 1e-9) else
                           f"the distance from the calibration data's rows or another input's allowance, "
                           f"larger there than this one's, up to {factor:.3g} ({rule})")
                    widened = (f", and the interval's scatter share is multiplied by up to {applied:.3g} "
                               f"({why})")
                warnings.append(f"{label} = {values}{unit} is {where}: an extrapolation ({bad.size} "
                                f"point(s)){widened}")
            inside &= ok
        if self.cloud is not None:
            ratio = self.cloud_ratio(points, shape) if ratio is None else ratio
            far = inside & (ratio > 1.0)
            if np.any(far):
                at = np.unravel_index(int(np.argmax(np.where(far, ratio, -np.inf))), shape) if shape else ()
                named = [c for c in self.cloud.columns if c in points or c in physics.PARAMETERS]
                columns = self.columns_at(points)
                example = ", ".join(_shown_value(c, (shown or {}).get(c), float(
                    np.broadcast_to(np.asarray(columns[c], dtype=float), shape)[at])) for c in named)
                warnings.append(
                    f"{int(np.sum(far))} point(s) lie within every column's range but far from the "
                    f"calibration data's rows (distance to the data, or departure from a line along which "
                    f"two of its columns move together, up to {float(np.max(ratio[far])):.2g} "
                    f"times what {100 * (1 - self.cloud.alpha):.0f} % of points like the data have; "
                    f"farthest: {example}): an extrapolation, and the interval's scatter share is widened by "
                    f"that ratio")
            inside &= ratio <= 1.0
        return inside, warnings

    def to_json(self) -> dict[str, Any]:
        """The model as JSON-ready data (numbers, strings, lists, dicts)."""
        return {
            "format_version": FORMAT_VERSION,
            "convention": self.convention,
            "fixed": dict(self.fixed),
            "fitted": {k: float(v) for k, v in self.fitted.items()},
            "terms": [term.to_json(values) for term, values in self.terms],
            "covariance": None if self.covariance is None else np.asarray(self.covariance).tolist(),
            "noise_std_log": self.noise_std_log,
            "domain": self.domain,
            "conditions": list(self.conditions),
            "discrepancy": None if self.discrepancy is None else self.discrepancy.state,
            "groups": [g.to_json() for g in self.groups],
            "scatter": None if self.scatter is None else self.scatter.to_json(),
            "cloud": None if self.cloud is None else self.cloud.to_json(),
            "domain_rows": self.domain_rows,
            "rivals": [r.to_json() for r in self.rivals],
            "clock": dict(self.clock),
            "headers": dict(self.headers),
            "edge_trends": {k: list(map(float, v)) for k, v in self.edge_trends.items()},
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> CalibratedModel:
        """Rebuild a model from :meth:`to_json` data (or a version 1 model), validating every part.

        Parameters
        ----------
        data : mapping
            As written by :meth:`to_json`, or by version 1 (``effect`` instead of ``terms``).

        Returns
        -------
        CalibratedModel

        Raises
        ------
        ValueError
            For an unknown format version, convention, parameter, effect or law, or a covariance
            of the wrong size.
        """
        version = data.get("format_version")
        if version not in (1, FORMAT_VERSION):
            raise ValueError(f"format_version must be 1 or {FORMAT_VERSION}; got {version!r}")
        convention = data.get("convention", physics.DEFAULT_CONVENTION)
        if convention not in physics.CONVENTIONS:
            raise ValueError(
                f"convention must be one of {', '.join(physics.CONVENTIONS)}; got {convention!r}"
            )
        values = {}
        for part in ("fixed", "fitted"):
            for name, value in dict(data.get(part, {})).items():
                if name not in physics.PARAMETERS:
                    raise ValueError(f"{part}: unknown physics parameter {name!r}")
                values[name] = physics.validate(name, value).item()
        fixed = {k: values[k] for k in dict(data.get("fixed", {}))}
        fitted = {k: values[k] for k in dict(data.get("fitted", {}))}
        if version == 1:
            effect = data.get("effect")
            terms = [] if effect is None else [term_from_json({**effect, "kind": "effect"})]
            return cls(fitted, fixed, terms, convention)
        terms = [term_from_json(t) for t in data.get("terms", [])]
        covariance = data.get("covariance")
        if covariance is not None:
            covariance = covariance_from_json(covariance, fitted, terms)
        noise = data.get("noise_std_log")
        domain = data.get("domain")
        if domain is not None:
            domain = {str(k): [float(v[0]), float(v[1])] for k, v in dict(domain).items()}
        discrepancy = data.get("discrepancy")
        return cls(
            fitted,
            fixed,
            terms,
            convention,
            covariance,
            None if noise is None else float(noise),
            domain,
            [str(c) for c in data.get("conditions", [])],
            None if discrepancy is None else GPCorrection(discrepancy),
            [GroupEffect.from_json(g) for g in data.get("groups") or []],
            None if data.get("scatter") is None else ScatterModel.from_json(data["scatter"]),
            None if data.get("cloud") is None else DataCloud.from_json(data["cloud"]),
            None if data.get("domain_rows") is None else int(data["domain_rows"]),
            [RivalModel.from_json(r) for r in data.get("rivals") or []],
            {str(k): str(v) for k, v in dict(data.get("clock") or {}).items()},
            {str(k): str(v) for k, v in dict(data.get("headers") or {}).items()},
            {str(k): [float(x) for x in v] for k, v in dict(data.get("edge_trends") or {}).items()},
        )

    @classmethod
    def from_fit(
        cls,
        result: FitResult,
        dataset: Dataset,
        convention: str,
        noise_std_log: float,
        *,
        discrepancy: Mapping[str, Any] | None = None,
        groups: Sequence[GroupEffect] = (),
        scatter: ScatterModel | None = None,
        cloud: DataCloud | None = None,
    ) -> CalibratedModel:
        """A model from a fit on a data set.

        Parameters
        ----------
        result : FitResult
            The fit (:func:`calibrate.fit.fit`): declared values, terms, their values and covariance.
        dataset : Dataset
            The data it was fitted on: its fixed values and conditions carry over, and its columns'
            ranges are the domain.
        convention : str
            See :data:`physics.CONVENTIONS`.
        noise_std_log : float
            Scatter of a new measurement of log μ. [1]
        discrepancy : mapping, optional
            A GP discrepancy's data (:func:`calibrate.discrepancy.gp_state`).
        groups : sequence of GroupEffect
            Random effects of factor columns.
        scatter : ScatterModel, optional
            The scatter model.
        cloud : DataCloud, optional
            The data cloud of the domain.

        Returns
        -------
        CalibratedModel
        """
        columns = dataset.columns()
        domain = {name: [float(np.min(v)), float(np.max(v))] for name, v in columns.items()}
        rows = len(next(iter(columns.values()))) if columns else None
        return cls(
            dict(result.declared),
            dict(dataset.fixed),
            [(t, list(map(float, v))) for t, v in zip(result.terms, result.term_values, strict=True)],
            convention,
            np.asarray(result.covariance, dtype=float),
            float(noise_std_log),
            domain,
            list(dataset.conditions),
            None if discrepancy is None else GPCorrection(discrepancy),
            list(groups),
            scatter,
            cloud,
            rows if cloud is not None else None,
            clock=dict(getattr(dataset, "clock", {})),
            headers=dict(getattr(dataset, "headers", {})),
        )


def _as_shown(name: str, reading: Any) -> tuple[str, Any, str]:
    """How a domain warning words column ``name``: its label, a function of a value (SI) to the value
    shown, and the unit after it (`` [N]``; none where the label states it): under the key a request sent
    it under and in that unit (:attr:`physics.columns.Reading.label`) when ``reading`` converted it, else
    its own name and unit."""
    if reading is not None and getattr(reading, "reading", ""):
        return reading.label, lambda v: float(reading.sent_value(float(v))), ""
    unit = f" [{physics.PARAMETERS[name].unit}]" if name in physics.PARAMETERS else ""
    return name, float, unit


def _shown_value(name: str, reading: Any, value: float) -> str:
    """``name = value`` as a domain warning gives a point (:func:`_as_shown`): ``RH [%] = 20``."""
    label, to_shown, _unit = _as_shown(name, reading)
    return f"{label} = {to_shown(value):.4g}"

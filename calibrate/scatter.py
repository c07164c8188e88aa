"""Scatter that depends on the conditions: a model of the spread of log μ around the calibrated model.

Friction scatters more in some regions than in others (stick-slip at low speed, a rough run-in). The
scatter model gives the standard deviation of log μ of a new measurement as a function of one input,
chosen by cross-validation among

* ``constant``: one spread everywhere (the model of every calibration before this one);
* ``step``: one spread below a split of one column and another above (a regression stump; the split
  among the column's 2-98 % quantiles, at least 8 rows either side, maximizes the likelihood on the
  training rows);
* ``loglinear``: log of the spread linear in the column, or in its log (a positive column: both are
  candidates, and cross-validation chooses, whatever the column's span: a spread that grows as a power
  of the load is linear in log load even over less than a decade), clipped to the column's range in
  the data.

Every candidate is fitted by Gaussian maximum likelihood of the held-out log residuals of the nested
cross-validation (so the spread holds the refit's uncertainty too; of the chosen terms, see
:func:`calibrate.select.held_out_of_chosen`), with rows beyond
:func:`calibrate.uncertainty.outlier_threshold` of the local spread left out (twice refitted), and
scored on k folds by the held-out negative log-likelihood, each row's square capped at that threshold
(gross outliers count like a few rows); the best of them is the form.

A new measurement's interval allows for the spread being estimated (:meth:`ScatterModel.quantile_factor`)
from the degrees of freedom ν that inform it locally: a step's k - 1 on each side; for ``loglinear``,
ν(x) = 1 / (2 Var[log ŝ(x)]), Var[log ŝ(x)] = (1, t) C (1, t)' with C = (X'X)⁻¹ / 2 the inverse
Fisher information of (a, b) (a Gaussian residual's log variance has information 1/2 per row), the
degrees of freedom of a variance estimate whose log has that variance (ν = n for one spread
everywhere). One spread everywhere, estimated from every row's held-out residual, takes Student's t
quantile of ν over the normal's (the prediction rule: the level on average over data sets). A spread
that varies takes the larger of that and the tolerance rule z_c sqrt(ν / χ²_{1-level, ν}) (an upper
confidence bound of the spread, at the interval's level, on the normal quantile of content 1 - 2 (1 -
level): 90 % of measurements in 95 % of data sets), the two rules of a new group's spread
(:meth:`calibrate.groups.GroupEffect.new_group_variance`): a step's side or a trend's end rests on the
rows of one region and on the trend's form there, and the interval must hold in that region, not only
over the data. The tolerance rule decides below about 40 degrees of freedom. For one spread everywhere
it had 8 and 12 rows cover 0.986 and 0.990 of fresh measurements (12 data sets each, above the
0.90-0.98 a 95 % interval should hold: on so few rows the interval holds two more margins, the refit's
uncertainty in the held-out residuals and the parameters' variance added at the point); the prediction
rule alone covers 0.966, 0.975 and, on 15 rows, 0.944.

Whether the scatter depends on the inputs at all is a **permutation test** (:func:`permutation_p`):
the statistic is the largest, over every column, of the step's likelihood ratio at its best split
and of the score statistic of a log-linear trend, on the residuals winsorized at the outlier threshold
of their robust scale; its null distribution comes from the same statistic on randomly permuted
residuals (under the null the residuals are exchangeable across rows, outliers and all). A
non-constant model is chosen only when p <= :data:`SCATTER_ALPHA` and it beats the constant one held
out: on data with one spread everywhere the scatter model stays constant with chance 1 - alpha. (A
paired z of the held-out losses has little power here: the scatter of a few rows carries the signal,
the many others only noise.)
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy import stats

from microbearing import physics

from .censored import residual_variance
from .fit import kfold_indices
from .tails import IntervalForm
from .uncertainty import outlier_threshold

__all__ = ["PERMUTATIONS", "SCATTER_ALPHA", "ScatterModel", "allowance", "fit_scatter", "noise_level",
           "permutation_p"]

#: Chance that a non-constant scatter model is chosen on data with one spread everywhere. [1]
SCATTER_ALPHA = 0.01
#: Random permutations of the test. [1]
PERMUTATIONS = 1000
#: Rows the choice of the scatter model (cross-validation, permutation test) uses at most (a random subset
#: of larger data, as the selection of terms searches 1,000 rows). [1]
MAX_TEST_ROWS = 1000
# Split candidates of a step: these quantiles of the column (every row's value, up to 200 of them).
_SPLITS = np.linspace(0.02, 0.98, 200)
# Fewest rows on either side of a step's split. [1]
_MIN_SIDE = 8
# Half the chi-square 95 % point with one degree of freedom: a split's profile likelihood interval.
_PROFILE_DROP = float(stats.chi2.ppf(0.95, 1) / 2.0)


def _transform(values: np.ndarray) -> str:
    v = np.asarray(values, dtype=float)
    return "log" if np.all(v > 0) and np.max(v) > 10.0 * np.min(v) else "linear"


@dataclass(frozen=True)
class ScatterModel:
    """Standard deviation of log μ as a function of one input.

    Attributes
    ----------
    kind : str
        ``constant``, ``step`` or ``loglinear``.
    column : str or None
        The input it depends on (None for ``constant``).
    coefficients : list of float
        ``constant``: [log sd]; ``step``: [log sd below, log sd above]; ``loglinear``: [a, b] with
        log sd = a + b t, t the standardized (log) column. [1]
    split : float or None
        A step's split, in the column's unit.
    band : list of float
        A step's 95 % likelihood interval of the split ([low, high], the column's unit: the splits whose
        profile log-likelihood lies within 1.92 of the best); between them the larger spread holds, so
        that an uncertain split does not give the quiet side's narrow interval to rows of the noisy one.
    transform : str
        ``log`` or ``linear``: how the column enters ``loglinear``.
    centre, scale : float
        Standardization of the (log) column for ``loglinear``.
    range : list of float
        The column's range in the data ([min, max], its unit); t is clipped to it.
    cv : dict
        Held-out negative log-likelihood of the constant and the chosen model per row [1], the paired
        z [1] and the z needed [1].
    rows : list of float
        A step's rows below and above its split. [1]
    covariance : list of float
        ``loglinear``: the inverse Fisher information of [a, b], flattened 2 x 2 (row-major) [1]; empty
        for the other kinds (and for models stored before it, whose intervals take no allowance).
    form : IntervalForm or None
        The degrees of freedom of one spread everywhere and the heavy-tail factor of the residuals
        (:mod:`calibrate.tails`); None for models stored before it (no allowance for ``constant``).
    """

    kind: str = "constant"
    column: str | None = None
    coefficients: list[float] = field(default_factory=lambda: [0.0])
    split: float | None = None
    transform: str = "linear"
    centre: float = 0.0
    scale: float = 1.0
    range: list[float] = field(default_factory=list)
    cv: dict[str, float] = field(default_factory=dict)
    band: list[float] = field(default_factory=list)
    rows: list[float] = field(default_factory=list)
    covariance: list[float] = field(default_factory=list)
    form: IntervalForm | None = None

    def quantile_factor(self, columns: Mapping[str, Any], shape: tuple[int, ...] = (), level: float = 0.95
                        ) -> np.ndarray:
        """The factor on the spread's half-width z ŝ at points [1] for the degrees of freedom ν that
        inform the spread there (see the module's text): :func:`allowance` of ν. A step's spread on each
        side rests on the k rows there (ν = k - 1); a log-linear one's on ν(x) = 1 / (2 Var[log ŝ(x)]). 1
        for one spread everywhere, and without row counts or covariance (models stored before them).
        With :attr:`form`, one spread everywhere takes the allowance of its degrees of freedom, and every
        kind the heavy-tail factor (:mod:`calibrate.tails`)."""
        tail = 1.0 if self.form is None else self.form.tail_factor
        return tail * self._dof_factor(columns, shape, level)

    def _dof_factor(self, columns: Mapping[str, Any], shape: tuple[int, ...], level: float) -> np.ndarray:
        if self.kind == "constant" and self.form is not None:
            # one spread everywhere, from every row: the prediction rule (see the module's text)
            return np.full(shape, _scalar_allowance(float(self.form.dof), level, tolerance=False))
        if self.kind == "loglinear" and len(self.covariance) == 4:
            t = self._standardized(columns, shape)
            (caa, cab), (_, cbb) = np.reshape(self.covariance, (2, 2))
            variance = np.maximum(caa + 2.0 * cab * t + cbb * t * t, 1e-12)
            return allowance(1.0 / (2.0 * variance), level)
        if self.kind != "step" or len(self.rows) != 2:
            return np.ones(shape)
        below, above = (_scalar_allowance(k - 1.0, level) for k in self.rows)
        x = np.broadcast_to(np.asarray(columns[self.column], dtype=float), shape)
        lo, hi = self.band or [self.split, self.split]
        return np.where(x < lo, below, np.where(x >= hi, above, max(below, above)))

    def _standardized(self, columns: Mapping[str, Any], shape: tuple[int, ...]) -> np.ndarray:
        """A log-linear model's t at points: the (log) column, clipped to its range, standardized. [1]"""
        x = np.clip(np.broadcast_to(np.asarray(columns[self.column], dtype=float), shape), *self.range)
        return ((np.log(x) if self.transform == "log" else x) - self.centre) / self.scale

    def std_log(self, columns: Mapping[str, Any], shape: tuple[int, ...] = ()) -> np.ndarray:
        """Standard deviation of log μ at points [1], broadcast to ``shape``.

        Raises
        ------
        KeyError
            When the column it depends on is missing.
        """
        if self.kind == "constant":
            return np.full(shape, float(np.exp(self.coefficients[0])))
        x = np.broadcast_to(np.asarray(columns[self.column], dtype=float), shape)
        if self.kind == "step":
            below, above = self.coefficients
            lo, hi = self.band or [self.split, self.split]
            return np.exp(np.where(x < lo, below, np.where(x >= hi, above, max(below, above))))
        a, b = self.coefficients
        return np.exp(a + b * self._standardized(columns, shape))

    def summary(self) -> str:
        """The scatter model in words, e.g. ``scatter 10 % below speed_m_s = 0.02 [m/s], 1.5 % above``."""
        unit = f" [{physics.PARAMETERS[self.column].unit}]" if self.column in physics.PARAMETERS else ""
        tested = ""
        if self.cv:
            tested = (f" (permutation p = {self.cv['p_value']:.3g} that the scatter is the same everywhere; "
                      f"the form chosen by cross-validation)")
        if self.kind == "constant":
            if self.cv:
                tested = (f" (that the scatter depends on no input is not rejected: permutation p = "
                          f"{self.cv['p_value']:.3g}, {self.cv['alpha']:.2g} needed)")
            return f"scatter {_pct(self.coefficients[0])} everywhere{tested}"
        if self.kind == "step":
            below, above = self.coefficients
            lo, hi = self.band or [self.split, self.split]
            return (f"scatter {_pct(below)} below {self.column} = {self.split:.4g}{unit}, {_pct(above)} "
                    f"above (the change lies between {lo:.4g} and {hi:.4g}{unit}, 95 % likelihood interval; "
                    f"the larger scatter is used there){tested}")
        lo, hi = self.range
        at = self.std_log({self.column: np.array([lo, hi])}, (2,))
        return (f"scatter {100 * at[0]:.3g} % at {self.column} = {lo:.4g}{unit} to {100 * at[1]:.3g} % at "
                f"{hi:.4g}{unit}, log-linear in {'log ' if self.transform == 'log' else ''}{self.column}"
                f"{tested}")

    def scaled(self, factor: float) -> ScatterModel:
        """The same shape with every spread multiplied by ``factor`` (> 0). [1]"""
        shift = float(np.log(factor))
        coefficients = ([c + shift for c in self.coefficients] if self.kind != "loglinear"
                        else [self.coefficients[0] + shift, self.coefficients[1]])
        return ScatterModel(self.kind, self.column, coefficients, self.split, self.transform, self.centre,
                            self.scale, self.range, self.cv, self.band, self.rows, self.covariance, self.form)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready data."""
        return {"kind": self.kind, "column": self.column, "coefficients": list(map(float, self.coefficients)),
                "split": self.split, "transform": self.transform, "centre": self.centre, "scale": self.scale,
                "range": list(map(float, self.range)), "cv": dict(self.cv),
                "band": list(map(float, self.band)), "rows": list(map(float, self.rows)),
                "covariance": list(map(float, self.covariance)),
                **({"form": self.form.to_json()} if self.form is not None else {})}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ScatterModel:
        """Rebuild from :meth:`to_json` data.

        Raises
        ------
        ValueError
            For an unknown kind or the wrong number of coefficients.
        """
        kind = str(data["kind"])
        sizes = {"constant": 1, "step": 2, "loglinear": 2}
        coefficients = [float(c) for c in data["coefficients"]]
        if kind not in sizes or len(coefficients) != sizes[kind]:
            raise ValueError(f"scatter: kind must be one of {', '.join(sizes)} with its coefficients; "
                             f"got {kind!r}")
        split = data.get("split")
        return cls(kind, data.get("column"), coefficients, None if split is None else float(split),
                   str(data.get("transform", "linear")), float(data.get("centre", 0.0)),
                   float(data.get("scale", 1.0)), [float(v) for v in data.get("range", [])],
                   {str(k): float(v) for k, v in dict(data.get("cv", {})).items()},
                   [float(v) for v in data.get("band", [])], [float(v) for v in data.get("rows", [])],
                   [float(v) for v in data.get("covariance", [])], IntervalForm.from_json(data.get("form")))


def allowance(dof: Any, level: float = 0.95, tolerance: bool = True) -> np.ndarray:
    """Factor [1] on z ŝ, z the normal quantile of ``level``, for a spread ŝ estimated with ``dof``
    degrees of freedom [1] (clipped to at least 1): the prediction rule t_ν / z, Student's t quantile of
    ν over the normal's (the level on average over data sets), and with ``tolerance`` the larger of it
    and the tolerance rule z_c sqrt(ν / χ²_{1-level, ν}) / z, z_c the normal quantile of content
    1 - 2 (1 - level) (the prediction rule alone when that content is not positive).

    Examples
    --------
    >>> [round(float(allowance(nu)), 4) for nu in (10, 40, 180)]
    [1.3369, 1.0312, 1.0068]
    >>> [round(float(allowance(nu, tolerance=False)), 4) for nu in (7, 10, 40, 180)]
    [1.2065, 1.1368, 1.0312, 1.0068]
    """
    nu = np.maximum(np.asarray(dof, dtype=float), 1.0)
    z = float(stats.norm.isf((1.0 - level) / 2.0))
    prediction = stats.t.isf((1.0 - level) / 2.0, nu) / z
    content = 1.0 - 2.0 * (1.0 - level)
    if not tolerance or content <= 0.0:
        return prediction
    z_content = float(stats.norm.isf((1.0 - content) / 2.0))
    return np.maximum(prediction, z_content * np.sqrt(nu / stats.chi2.ppf(1.0 - level, nu)) / z)


@functools.lru_cache(maxsize=1024)
def _scalar_allowance(dof: float, level: float, tolerance: bool = True) -> float:
    """:func:`allowance` of one number of degrees of freedom, remembered: a model's constant or step
    spread asks it at every prediction with the same numbers."""
    return float(allowance(dof, level, tolerance))


def _pct(log_sd: float) -> str:
    return f"{100 * float(np.exp(log_sd)):.3g} %"


def _fit_one(kind: str, column: str | None, x: np.ndarray | None, r: np.ndarray, threshold: float,
             transform: str = "linear") -> ScatterModel | None:
    """Maximum-likelihood fit of one candidate on rows r (and column values x, entering ``loglinear`` as
    they are or by their log, ``transform``), outliers trimmed."""
    keep = np.ones(r.size, dtype=bool)
    model: ScatterModel | None = None
    for _ in range(3):
        rk = r[keep]
        if kind == "constant":
            model = ScatterModel("constant", None, [0.5 * float(np.log(max(np.mean(rk * rk), 1e-24)))])
        elif kind == "step":
            profile = _step_profile(x[keep], rk, np.unique(np.quantile(x, _SPLITS)))
            if profile is None:
                return None
            nll, splits, log_sd, below = profile
            best = int(np.argmin(nll))
            near = splits[nll <= nll[best] + _PROFILE_DROP]
            model = ScatterModel("step", column, [float(log_sd[best, 0]), float(log_sd[best, 1])],
                                 float(splits[best]), range=[float(np.min(x)), float(np.max(x))],
                                 band=[float(near.min()), float(near.max())],
                                 rows=[float(below[best]), float(rk.size - below[best])])
        else:
            tx = np.log(x) if transform == "log" else x
            centre, scale = float(np.mean(tx)), float(np.std(tx))
            if scale <= 0:
                return None
            t = ((tx - centre) / scale)[keep]
            p = _loglinear(t, rk * rk)
            # Inverse Fisher information of (a, b) of log sd: a Gaussian residual's log variance carries
            # information 1/2 per row, its log sd 2, so C = (X'X)^-1 / 2.
            design = np.column_stack([np.ones_like(t), t])
            covariance = 0.5 * np.linalg.pinv(design.T @ design)
            model = ScatterModel("loglinear", column, [float(p[0]), float(p[1])], None, transform, centre,
                                 scale, [float(np.min(x)), float(np.max(x))],
                                 covariance=[float(v) for v in covariance.ravel()])
        sd = model.std_log({column: x} if column else {}, r.shape)
        new_keep = np.abs(r / sd) <= threshold
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return model


def _step_profile(x: np.ndarray, r: np.ndarray, splits: np.ndarray):
    """The profile likelihood of a step in the scatter at each split (rows with ``x < split`` below it),
    for the splits leaving at least :data:`_MIN_SIDE` rows on each side: negative log-likelihood, the
    splits, the log sd below and above, and the rows below; None when no split qualifies. One sort and
    cumulative sums of the squares stand for a pass over the rows per split."""
    order = np.argsort(x, kind="stable")
    squares = np.concatenate([[0.0], np.cumsum(r[order] ** 2)])
    below = np.searchsorted(x[order], splits, side="left")
    above = r.size - below
    ok = (below >= _MIN_SIDE) & (above >= _MIN_SIDE)
    if not ok.any():
        return None
    below, above, splits = below[ok], above[ok], splits[ok]
    variance = np.column_stack([np.maximum(squares[below] / below, 1e-24),
                                np.maximum((squares[-1] - squares[below]) / above, 1e-24)])
    nll = 0.5 * (below * np.log(variance[:, 0]) + above * np.log(variance[:, 1]))
    return nll, splits, 0.5 * np.log(variance), below


def _loglinear(t: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """Maximum-likelihood [a, b] of log sd = a + b t for zero-mean Gaussian residuals with squares ``r2``:
    Fisher scoring of the gamma GLM of ``r2`` with log link (unit weights), halving a step that does not
    lower the negative log-likelihood."""
    design = np.column_stack([np.ones_like(t), t])
    gram = np.linalg.pinv(design.T @ design)
    eta = np.full(t.shape, float(np.log(max(np.mean(r2), 1e-300))))

    def nll(eta):
        return float(np.sum(eta + r2 * np.exp(-eta)))

    beta = np.array([eta[0], 0.0])
    current = nll(eta)
    for _ in range(50):
        step = gram @ (design.T @ (r2 * np.exp(-eta) - 1.0))
        for _ in range(20):
            trial = beta + step
            value = nll(design @ trial)
            if value <= current:
                break
            step = step / 2
        else:
            break
        converged = abs(current - value) <= 1e-10 * max(abs(current), 1.0)
        beta, current, eta = trial, value, design @ trial
        if converged:
            break
    return beta / 2.0  # log variance -> log sd


def _held_out_loss(model: ScatterModel, column: str | None, x: np.ndarray | None, r: np.ndarray,
                   threshold: float) -> np.ndarray:
    sd = model.std_log({column: x} if column else {}, r.shape)
    z2 = np.minimum((r / sd) ** 2, threshold**2)
    return np.log(sd) + 0.5 * z2


def fit_scatter(columns: Mapping[str, np.ndarray], residual: np.ndarray, folds: int = 5, seed: int = 0,
                alpha: float = SCATTER_ALPHA) -> ScatterModel:
    """Choose and fit the scatter model by cross-validation.

    The choice (cross-validation and permutation test) runs on at most :data:`MAX_TEST_ROWS` rows, a
    random subset of larger data; the chosen model is then fitted on every row.

    Parameters
    ----------
    columns : mapping of str to numpy.ndarray
        Inputs that vary in the data (physics columns and numeric conditions), one value per row.
    residual : numpy.ndarray
        Held-out ``log(mu_measured / mu_predicted)`` of every row (nested cross-validation). [1]
    folds : int
        Folds of the choice. [1]
    seed : int
        Seed of the folds.
    alpha : float
        Chance of choosing a non-constant model when the spread is the same everywhere. [1]

    Returns
    -------
    ScatterModel
        With ``cv``: the held-out losses and the paired z of the chosen model against the constant one.
    """
    everything = np.asarray(residual, dtype=float)
    all_columns = {k: np.asarray(v, dtype=float) for k, v in columns.items()
                   if np.unique(np.asarray(v, dtype=float)).size > 1}
    # The choice runs on at most MAX_TEST_ROWS rows (a random subset); the chosen model is fitted on all.
    chosen_rows = (np.arange(everything.size) if everything.size <= MAX_TEST_ROWS else
                   np.sort(np.random.default_rng(seed).choice(everything.size, MAX_TEST_ROWS, replace=False)))
    r = everything[chosen_rows]
    n = r.size
    threshold = outlier_threshold(n)
    varying = {k: v[chosen_rows] for k, v in all_columns.items()}
    # A log-linear trend in the column, and in its log when the column is positive.
    candidates = [("constant", None, "linear")] + [
        (kind, c, transform) for c in varying for kind, transform in
        (("step", "linear"), ("loglinear", "linear"), ("loglinear", "log")) if transform == "linear" or
        np.all(all_columns[c] > 0)]
    test_rows = kfold_indices(n, min(folds, n), seed)
    losses: dict[tuple[str, str | None, str], np.ndarray] = {}
    for kind, column, transform in candidates:
        x = varying.get(column) if column else None
        loss = np.empty(n)
        ok = True
        for test in test_rows:
            train = np.setdiff1d(np.arange(n), test)
            model = _fit_one(kind, column, None if x is None else x[train], r[train], threshold, transform)
            if model is None:
                ok = False
                break
            loss[test] = _held_out_loss(model, column, None if x is None else x[test], r[test], threshold)
        if ok:
            losses[(kind, column, transform)] = loss
    constant = losses[("constant", None, "linear")]

    gains = {key: float(np.mean(constant - loss)) for key, loss in losses.items() if key[0] != "constant"}
    best = max(gains, key=lambda key: gains[key], default=None)
    p_value = permutation_p(varying, r, seed) if varying else 1.0
    cv = {"loss_constant": float(np.mean(constant)), "p_value": p_value, "alpha": alpha}
    r, varying, threshold = everything, all_columns, outlier_threshold(everything.size)
    if best is None or p_value > alpha or gains[best] <= 0:
        model = _fit_one("constant", None, None, r, threshold)
        return ScatterModel(model.kind, None, model.coefficients,
                            cv={**cv, "loss_chosen": cv["loss_constant"]})
    kind, column, transform = best
    model = _fit_one(kind, column, varying[column], r, threshold, transform)
    return replace(model, cv={**cv, "loss_chosen": float(np.mean(losses[best]))})


def _statistics(w2: np.ndarray, orders: list[np.ndarray], splits: list[np.ndarray],
                trends: list[np.ndarray]) -> np.ndarray:
    """Largest step likelihood ratio and trend score statistic over the columns, per row of ``w2``
    (shape (draws, rows): squared winsorized residuals, each draw a permutation). [1]"""
    draws, n = w2.shape
    total = w2.sum(axis=1)
    best = np.zeros(draws)
    k = np.arange(1, n)
    for order, valid in zip(orders, splits, strict=True):
        below = np.cumsum(w2[:, order], axis=1)[:, :-1]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = (n * np.log(total / n)[:, None] - k * np.log(below / k)
                     - (n - k) * np.log((total[:, None] - below) / (n - k)))
        best = np.maximum(best, np.max(np.where(valid[None, :], np.nan_to_num(ratio, nan=0.0), 0.0), axis=1))
    centred = w2 - w2.mean(axis=1, keepdims=True)
    spread = np.sqrt(np.sum(centred**2, axis=1))
    for t in trends:
        # Koenker's studentized score statistic of a log-linear trend in t: n R^2 of w2 on t.
        correlation = centred @ t / np.maximum(spread * np.sqrt(np.sum(t * t)), 1e-300)
        best = np.maximum(best, n * correlation**2)
    return best


def permutation_p(columns: Mapping[str, np.ndarray], residual: np.ndarray, seed: int = 0,
                  permutations: int = PERMUTATIONS) -> float:
    """Permutation p-value that the scatter of ``residual`` depends on no column (see the module's text).

    Parameters
    ----------
    columns : mapping of str to numpy.ndarray
        Columns that vary, one value per row.
    residual : numpy.ndarray
        Log residuals. [1]
    seed : int
        Seed of the permutations (and of the subset of larger data).
    permutations : int
        Random permutations. [1]

    Returns
    -------
    float
        ``(1 + #{permuted statistic >= observed}) / (1 + permutations)``. [1]
    """
    r = np.asarray(residual, dtype=float)
    rng = np.random.default_rng(seed)
    rows = np.arange(r.size) if r.size <= MAX_TEST_ROWS else np.sort(rng.choice(r.size, MAX_TEST_ROWS,
                                                                                 replace=False))
    r = r[rows]
    n = r.size
    scale = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    if scale <= 0:
        return 1.0
    w2 = np.square(np.clip(r, -outlier_threshold(n) * scale, outlier_threshold(n) * scale) / scale)
    orders, splits, trends = [], [], []
    for values in columns.values():
        x = np.asarray(values, dtype=float)[rows]
        order = np.argsort(x, kind="stable")
        ordered = x[order]
        k = np.arange(1, n)
        splits.append((ordered[1:] > ordered[:-1]) & (k >= _MIN_SIDE) & (n - k >= _MIN_SIDE))
        orders.append(order)
        t = np.log(x) if _transform(x) == "log" else x
        trends.append(t - t.mean())
    observed = _statistics(w2[None, :], orders, splits, trends)[0]
    exceed = 0
    for start in range(0, permutations, 250):
        draws = min(250, permutations - start)
        shuffled = w2[np.argsort(rng.random((draws, n)), axis=1)]
        exceed += int(np.sum(_statistics(shuffled, orders, splits, trends) >= observed - 1e-12))
    return (1 + exceed) / (1 + permutations)


def noise_level(scatter: ScatterModel, gp_state: Mapping[str, Any] | None, held_out: np.ndarray,
                 inliers: np.ndarray, varying: Mapping[str, np.ndarray],
                 shape: tuple[int, ...], censored: np.ndarray | None = None) -> tuple[float, ScatterModel]:
    """The scatter of a new measurement around the model (std of log μ [1]) and the scatter model at
    that level: from ``held_out``, the held-out log residual of the chosen terms (RMS over ``inliers``, a
    clipped row by its side of the clip), or the white noise of the GP on what the terms leave
    (``gp_state``, :func:`calibrate.discrepancy.residual_gp`'s ``gp``). Stage 4 of
    :func:`calibrate.calibrate`."""
    if gp_state is None:
        # A new measurement scatters around the model as the held-out rows of the nested
        # cross-validation did: noise, what the terms leave, and the refit's own uncertainty. RMS over
        # the rows that are not outliers (a median-based scale would be robust too, but it scatters
        # twice as much from one data set to the next).
        noise_variance = residual_variance(held_out, censored, inliers)
    else:
        # What the terms leave is the GP's, with its own predictive variance at each point; the
        # noise is its white-noise part (Kennedy-O'Hagan), not the held-out scatter, which holds both.
        noise_variance = gp_state["noise"] * float(np.var(gp_state["y"]))
    noise_std_log = float(np.sqrt(noise_variance))
    if scatter.kind != "constant" and gp_state is not None:
        # The scatter model's shape at the level of the GP's white noise (RMS over the rows that are not
        # outliers). Without a GP it stays as fitted: the maximum-likelihood spread of these held-out
        # residuals in each region (an RMS of the spreads would be set by the noisiest rows and would
        # rescale the quiet ones with them).
        rms = float(np.sqrt(np.mean(np.square(scatter.std_log(varying, shape)[inliers]))))
        scatter = scatter.scaled(noise_std_log / rms)
    elif scatter.kind == "constant":
        scatter = scatter.scaled(noise_std_log / float(np.exp(scatter.coefficients[0])))
    return noise_std_log, scatter

"""The lab's measurement system: replicates, a clipping sensor, constant data, and the instrument's drift.

What a tribometer does to the readings is not the bearing's physics, and the calibration says so
before it reads the data as physics:

* **Replicates.** Rows with the same inputs and conditions (up to a jitter of
  :data:`JITTER` relative, order and time columns aside) are one **design point** measured several
  times. Their spread about their own mean is the **pure error**: the scatter of the measurement
  itself, whatever the model. The model's residual sum of squares (of log μ) splits into pure error and
  **lack of fit**, the spread of the design points' mean residuals, and the F-test of the two says
  whether the model misses something the replicates can see (NIST/SEMATECH e-Handbook of Statistical
  Methods, 4.4.4.4; :func:`lack_of_fit`). Cross-validation folds then keep a design point's replicates
  together (:func:`folds`): a held-out row whose replicate was in training is predicted by its twin,
  not by the model.
* **Saturation.** A pile of identical readings at the top or the bottom of μ (a sensor at its clip)
  is found (:func:`inspect`) and those rows are censored: they say the true μ is beyond the clip, and
  enter the fit by that probability (:mod:`calibrate.censored`), not as values.
* **Constant data.** μ identical in every row tells nothing a term could follow: said, and no term.
* **Unit slips in part of the rows.** A few rows of an input or condition (at least
  :data:`_SLIP_MIN_ROWS`, at most :data:`_SLIP_MAX_SHARE` of them) sitting a unit's factor
  (:data:`SLIP_FACTORS`: percent, a prefix step, a millionth) away from the others, with no row within a
  factor 10 between, and back among the others once scaled by it (a load in N in a mN column) are said
  and left out (:func:`unit_slips`): read as physics they were a law (a load law, a GP) or a scatter of
  15-20 % for a true 3 %.
* **Drift.** An order (``run_index``) or time column (ISO 8601 times read as hours,
  :mod:`calibrate.data`) is a candidate driver of the effect ``measurement_drift`` (the reading drifts
  over the session: gauge drift, AIAG MSA), distinct from a run-in of the bearing with its cycles, and of
  ``measurement_step`` (the reading steps once, at a place searched between the column's values: a
  recalibrated load cell); when the search chooses one the report says how far the instrument drifted
  or where and how far it stepped (:func:`drift_words`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime, timedelta
from typing import Any

import numpy as np
from scipy import sparse, stats
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from microbearing.physics.columns import physical_range

from .candidates import Term
from .censored import measured_rows
from .data import Dataset
from .fit import Z95, fit, kfold_indices, robust_scale

__all__ = ["JITTER", "SLIP_FACTORS", "LackOfFit", "MeasurementSystem", "Saturation", "UnitSlip",
           "drift_words", "folds", "inspect", "lack_of_fit", "slip_factors", "unit_slips",
           "with_censor_scale"]

#: Relative jitter within which two values of an input are one level of a design (log scale for a
#: positive column, of the column's range otherwise). [1]
JITTER = 0.02
#: A pile of identical readings at an end of μ is a clip when it holds at least this share of the rows
#: (and :data:`_PILE_MIN` rows, and :data:`_PILE_OVER_TIES` times the most frequent other value). [1]
PILE_SHARE = 0.05
_PILE_MIN = 5
_PILE_OVER_TIES = 3
# A design needs at least this many points per fold for folds of whole points. [1]
_POINTS_PER_FOLD = 1
#: Factors of a unit slip: percent written in a fraction's column (100), a prefix step (1000: N in a mN
#: column, m/s in a mm/s one), a millionth (1e6: µN in an N column). [1] Percent only in a column whose
#: physical range ends at 1 (:func:`slip_factors`): a load or speed design of two levels a factor 100
#: apart is a design, no unit's slip.
SLIP_FACTORS = (1e2, 1e3, 1e6)
# Rows on the slip's side of the gap at least, and their share of the rows at most. [1]
_SLIP_MIN_ROWS = 3
_SLIP_MAX_SHARE = 0.25
# The gap's width in decades at least (no row within a factor 10), and how far in decades the two sides'
# medians may be from a factor of SLIP_FACTORS and the slipped rows, scaled, beyond the others' range. [1]
_SLIP_GAP = 1.0
_SLIP_TOLERANCE = 0.3


@dataclass(frozen=True)
class Saturation:
    """A pile of identical readings at one end of μ.

    Attributes
    ----------
    side : str
        ``"upper"`` (the true μ is at least the clip) or ``"lower"`` (at most).
    level : float
        The clipped reading. [1]
    rows : int
        Rows at it. [1]
    share : float
        Their share of the rows. [1]
    """

    side: str
    level: float
    rows: int
    share: float

    def words(self) -> str:
        """The clip in words."""
        beyond = "at least" if self.side == "upper" else "at most"
        return (f"{self.rows} rows ({100 * self.share:.0f} %) read exactly mu = {self.level:.6g}, the "
                f"{'largest' if self.side == 'upper' else 'smallest'} value: a sensor at its clip; they are "
                f"censored (the true mu is {beyond} {self.level:.6g}) and enter the fit by that "
                f"probability (Tobit likelihood), not as values")


@dataclass(frozen=True)
class UnitSlip:
    """Rows of one column a unit's factor away from the others (:func:`unit_slips`).

    Attributes
    ----------
    column : str
        The column as sent (its header or JSON key).
    factor : float
        The unit's factor, one of :data:`SLIP_FACTORS`. [1]
    below : bool
        Whether the slipped rows read ``factor`` times below the others (else above).
    rows : tuple of int
        The slipped rows, 0-based, of the rows as sent.
    share : float
        Their share of the rows. [1]
    gap : float
        The empty gap between them and the others, a factor. [1]
    """

    column: str
    factor: float
    below: bool
    rows: tuple[int, ...]
    share: float
    gap: float

    def words(self) -> str:
        """The slip in words, its rows numbered from 1."""
        listed = ", ".join(str(r + 1) for r in self.rows[:10]) + (", ..." if len(self.rows) > 10 else "")
        factor, side = f"{self.factor:g}", "below" if self.below else "above"
        return (f"{self.column}: {len(self.rows)} rows ({100 * self.share:.0f} %) read about {factor}x "
                f"{side} the others, none within a factor {self.gap:.3g} between them, and x {factor} fall "
                f"among them (rows {listed}): a unit slip (written in a unit {factor}x "
                f"{'larger' if self.below else 'smaller'} than the column's); those rows are left out of "
                f"the fit, not read as physics")

    def to_json(self) -> dict[str, Any]:
        """The slip as data (rows 1-based), with ``summary`` in words."""
        return {"column": self.column, "factor": self.factor, "below": self.below,
                "rows": [r + 1 for r in self.rows], "share": self.share, "gap": self.gap,
                "summary": self.words()}


@dataclass(frozen=True)
class LackOfFit:
    """The residual sum of squares of log μ split into pure error and lack of fit (F-test).

    Attributes
    ----------
    points : int
        Design points with a measured row. [1]
    replicated : int
        Of them, points measured more than once. [1]
    rows : int
        Measured rows counted. [1]
    pure_error : float
        Standard deviation of log μ within design points (the measurement's own scatter). [1]
    pure_error_dof : int
        Its degrees of freedom, rows - points. [1]
    lack_of_fit_dof : int
        Points - fitted values (0: no test). [1]
    f : float or None
        Lack-of-fit mean square over pure-error mean square. [1]
    p : float or None
        Chance of an F at least as large when the model lacks nothing. [1]
    outliers : int
        Rows left out as outliers (not counted in ``rows``). [1]
    clipped : int
        Rows left out as clipped by the sensor (their reading is no value). [1]
    """

    points: int
    replicated: int
    rows: int
    pure_error: float
    pure_error_dof: int
    lack_of_fit_dof: int
    f: float | None
    p: float | None
    outliers: int = 0
    clipped: int = 0

    def words(self) -> str:
        """E.g. ``20 design points x 5 (100 rows); pure error 3.1 %; lack of fit p = 0.42 (F = 1.04 ...)``."""
        per = self.rows / self.points
        counts = f"{per:.0f}" if abs(per - round(per)) < 1e-9 else f"{per:.1f} on average"
        left = [f"{k} {what}{'s' * (k > 1)} left out"
                for k, what in ((self.outliers, "outlier"), (self.clipped, "clipped row")) if k]
        text = (f"{self.points} design points x {counts} ({self.rows} rows, {self.replicated} points "
                f"replicated{''.join('; ' + w for w in left)}); pure error {100 * self.pure_error:.1f} % "
                f"(scatter of log mu between replicates, {self.pure_error_dof} degrees of freedom)")
        if self.p is None:
            return text + "; no lack-of-fit test: as many fitted values as design points"
        # the words follow the p-value: strong below 1 %, a sign below 5 %, none above
        verdict = ("the model misses something the replicates see" if self.p < 0.01 else
                   "a sign that the model misses something the replicates see (p below 0.05, not below "
                   "0.01)" if self.p < 0.05 else
                   "the model fits the design points' means as well as the replicates allow")
        return (text + f"; lack of fit p = {self.p:.3g} (F = {self.f:.3g} on {self.lack_of_fit_dof} and "
                f"{self.pure_error_dof} degrees of freedom): {verdict}")

    def to_json(self) -> dict[str, Any]:
        """The figures as data, with ``summary`` in words."""
        return {"points": self.points, "replicated_points": self.replicated, "rows": self.rows,
                "pure_error_relative": self.pure_error, "pure_error_dof": self.pure_error_dof,
                "lack_of_fit_dof": self.lack_of_fit_dof, "f": self.f, "p": self.p,
                "outliers_left_out": self.outliers, "clipped_left_out": self.clipped, "summary": self.words()}


@dataclass(frozen=True)
class MeasurementSystem:
    """What the data say about the measurement system before any fit (:func:`inspect`).

    Attributes
    ----------
    design : numpy.ndarray or None
        Design point of each row when some are replicated, else None.
    sessions : tuple of str
        Order and time columns (candidate drivers of ``measurement_drift``, not of the design).
    clock : dict of str to str
        Time columns read from ISO 8601 and their start.
    saturation : tuple of Saturation
        Clips found (at most one per end).
    constant : float or None
        The one value of μ when every row reads it, else None. [1]
    grouped_folds : bool
        Whether folds keep design points whole (enough points for the folds).
    slips : tuple of UnitSlip
        Unit slips found (:func:`unit_slips`); their rows are left out (:meth:`apply`).
    kept : numpy.ndarray or None
        Rows as sent that the calibration reads (0-based), when slips left some out; else None.
    """

    design: np.ndarray | None
    sessions: tuple[str, ...]
    clock: dict[str, str]
    saturation: tuple[Saturation, ...]
    constant: float | None
    grouped_folds: bool = False
    slips: tuple[UnitSlip, ...] = ()
    kept: np.ndarray | None = field(default=None, repr=False)

    def censored(self, mu: np.ndarray) -> np.ndarray | None:
        """+1 / -1 / 0 per row for the clips (None when there is none)."""
        if not self.saturation:
            return None
        out = np.zeros(mu.size, dtype=np.int8)
        for clip in self.saturation:
            out[mu == clip.level] = 1 if clip.side == "upper" else -1
        return out

    def apply(self, dataset: Dataset) -> Dataset:
        """The data as sent without the rows of unit slips, their design points and censored rows marked
        (:class:`calibrate.data.Dataset`)."""
        dataset = dataset if self.kept is None else dataset.subset(self.kept)
        return replace(dataset, design=self.design, censored=self.censored(dataset.mu_measured))

    def words(self) -> list[str]:
        """What was found, one sentence each (empty when nothing)."""
        out = [slip.words() for slip in self.slips]
        if self.constant is not None:
            out.append(f"every row reads mu = {self.constant:.6g}: constant data show no dependence on "
                       f"anything measured (a stuck or saturated sensor?); no term is fitted")
        out += [clip.words() for clip in self.saturation]
        out += [f"{name} read as time: hours since {start}" for name, start in self.clock.items()]
        if self.sessions:
            out.append(f"order/time column(s) {', '.join(self.sessions)}: candidate driver(s) of a "
                       f"measurement drift (the reading, not the bearing), left out of the design points")
        if self.design is not None:
            how = ("cross-validation folds keep each point's replicates together" if self.grouped_folds else
                   "too few design points to keep each one in a single fold: folds split rows")
            out.append(f"{np.unique(self.design).size} design points for {self.design.size} rows: {how}")
        return out


def _scaled(values: np.ndarray) -> np.ndarray:
    """A column on the scale of :data:`JITTER`: log of a positive column, else its fraction of the range."""
    x = np.asarray(values, dtype=float)
    if np.all(x > 0):
        return np.log(x)
    span = np.ptp(x)
    return (x - x.min()) / span if span > 0 else np.zeros_like(x)


def _design(dataset: Dataset, sessions: Sequence[str]) -> np.ndarray | None:
    """Design point of each row when at least two points hold replicates, at most half as many points as
    rows, and some degrees of freedom remain for pure error; else None.

    Two rows are one point when they lie within :data:`JITTER` of each other in every column at once (and
    share every factor label), linked in chains; a chain longer than a point's jitter allows (a column
    spanning more than 2 JITTER: the rows of a continuous design, not the replicates of one point) is no
    point, its rows each their own. Judged jointly, a design whose points are drawn at random (two points
    close in one column, never in all) keeps its replicates, and one point measured with a larger jitter
    loses only its own.
    """
    n = dataset.n_points
    x = [_scaled(v) for name, v in dataset.columns().items() if name not in sessions]
    # a factor's labels apart by more than the jitter: one point never spans two
    x += [np.unique(v, return_inverse=True)[1].astype(float) for v in dataset.factors.values()]
    if not x:
        return np.zeros(n, dtype=int)
    x = np.stack(x, axis=1)
    pairs = cKDTree(x).query_pairs(JITTER * (1 + 1e-9), p=np.inf, output_type="ndarray")
    graph = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    point = connected_components(graph, directed=False)[1]
    low = np.full((point.max() + 1, x.shape[1]), np.inf)
    high = np.full_like(low, -np.inf)
    np.minimum.at(low, point, x)
    np.maximum.at(high, point, x)
    chained = np.any(high - low > 2 * JITTER * (1 + 1e-9), axis=1)[point]
    # a chain's rows: each its own point (rows of identical values stay one)
    exact = np.unique(x[chained], axis=0, return_inverse=True)[1].ravel()
    point[chained] = point.max() + 1 + exact
    point = np.unique(point, return_inverse=True)[1].ravel()
    counts = np.bincount(point)
    if np.sum(counts > 1) < 2 or counts.size > n / 2:
        return None
    return point


def _saturation(mu: np.ndarray) -> tuple[Saturation, ...]:
    values, counts = np.unique(mu, return_counts=True)
    if values.size < 3:
        return ()
    found = []
    # each end's pile against the ties between the ends: a sensor clipped at both ends has two piles, and
    # neither may hide the other
    between = counts[1:-1].max()
    for index, side in ((-1, "upper"), (0, "lower")):
        pile = counts[index]
        if pile >= max(_PILE_MIN, PILE_SHARE * mu.size) and pile >= _PILE_OVER_TIES * between:
            found.append(Saturation(side, float(values[index]), int(pile), float(pile / mu.size)))
    return tuple(found)


def inspect(dataset: Dataset, n_folds: int) -> MeasurementSystem:
    """Replicates, clips, constant data and order/time columns of the measurements.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    n_folds : int
        Cross-validation folds: folds keep design points whole only with at least as many points. [1]

    Returns
    -------
    MeasurementSystem

    Examples
    --------
    >>> from microbearing.calibrate.data import parse_rows
    >>> rows = [{"load_N": g * (1 + 0.001 * k), "run_index": 3 * i + k, "mu_measured": 0.01 + 0.001 * k}
    ...         for i, g in enumerate([0.01, 0.02, 0.04]) for k in range(3)]
    >>> system = inspect(parse_rows(rows, fixed={"balls": 4, "speed_m_s": 0.1}), 3)
    >>> system.design.tolist(), system.sessions, system.grouped_folds
    ([0, 0, 0, 1, 1, 1, 2, 2, 2], ('run_index',), True)
    """
    sessions = dataset.session_columns()
    slips = unit_slips(dataset, sessions)
    kept = None
    if slips:  # left out only when the folds keep two rows each and at least half the rows remain
        kept = np.setdiff1d(np.arange(dataset.n_points), np.concatenate([s.rows for s in slips]))
        slips, kept = ((), None) if kept.size < max(2 * n_folds, dataset.n_points / 2) else (slips, kept)
    dataset = dataset if kept is None else dataset.subset(kept)
    mu = dataset.mu_measured
    constant = float(mu[0]) if np.unique(mu).size == 1 else None
    design = _design(dataset, sessions)
    grouped = design is not None and np.unique(design).size >= _POINTS_PER_FOLD * n_folds
    return MeasurementSystem(design, sessions, dict(dataset.clock),
                             () if constant is not None else _saturation(mu), constant, grouped, slips, kept)


def slip_factors(name: str) -> tuple[float, ...]:
    """The factors of :data:`SLIP_FACTORS` a unit slip of the column ``name`` can take: percent (100)
    only in a fraction's column (physical range ending at 1, :func:`physics.columns.physical_range`), the
    prefix steps in every other.

    >>> slip_factors("relative_humidity"), slip_factors("load_N")
    ((100.0, 1000.0, 1000000.0), (1000.0, 1000000.0))
    """
    fraction = physical_range(name)[1] == 1.0
    return tuple(f for f in SLIP_FACTORS if fraction or f != 1e2)


def unit_slips(dataset: Dataset, sessions: Sequence[str] = ()) -> tuple[UnitSlip, ...]:
    """Unit slips in part of the rows: in a positive column (order and time columns aside), the rows on
    the far side of its widest empty gap in log scale (at least :data:`_SLIP_GAP` decades), when they are
    :data:`_SLIP_MIN_ROWS` or more and at most :data:`_SLIP_MAX_SHARE` of the rows, their median a factor
    of :data:`SLIP_FACTORS` from the others' (within :data:`_SLIP_TOLERANCE` decades), and, scaled by it,
    every one of them within the others' range (as widened by the tolerance). A design that spans decades
    without a gap, or a column with a few values near zero (a uniform draw from 0), has no such rows.

    Examples
    --------
    >>> from microbearing.calibrate.data import parse_rows
    >>> loads = [0.003 * 1.1 ** k for k in range(24)]
    >>> loads[2], loads[9], loads[17] = loads[2] / 1000, loads[9] / 1000, loads[17] / 1000
    >>> rows = [{"load_N": g, "mu_measured": 0.01} for g in loads]
    >>> d = parse_rows(rows, fixed={"balls": 4, "speed_m_s": 0.1})
    >>> [(s.column, s.factor, s.below, s.rows) for s in unit_slips(d)]
    [('load_N', 1000.0, True, (2, 9, 17))]
    """
    found = []
    for name, values in dataset.columns().items():
        x = np.asarray(values, dtype=float)
        if name in sessions or x.size < 4 * _SLIP_MIN_ROWS or not np.all(np.isfinite(x) & (x > 0)):
            continue
        order = np.argsort(x, kind="stable")
        logs = np.log10(x[order])
        k = int(np.argmax(np.diff(logs)))
        gap = float(logs[k + 1] - logs[k])
        below = k + 1 <= x.size - k - 1  # the slipped side is the smaller one
        slipped, others = (order[:k + 1], order[k + 1:]) if below else (order[k + 1:], order[:k + 1])
        if gap < _SLIP_GAP or not _SLIP_MIN_ROWS <= slipped.size <= _SLIP_MAX_SHARE * x.size:
            continue
        apart = abs(float(np.median(np.log10(x[others])) - np.median(np.log10(x[slipped]))))
        rest = np.log10(x[others])
        for factor in slip_factors(name):
            moved = np.log10(x[slipped]) + (np.log10(factor) if below else -np.log10(factor))
            tol = _SLIP_TOLERANCE
            if (abs(apart - np.log10(factor)) <= tol and moved.min() >= rest.min() - tol
                    and moved.max() <= rest.max() + tol):
                found.append(UnitSlip(dataset.headers.get(name, name), factor, below,
                                      tuple(int(i) for i in np.sort(slipped)), slipped.size / x.size,
                                      10.0 ** gap))
                break
    return tuple(found)


def folds(dataset: Dataset, n_folds: int, seed: int = 0) -> list[np.ndarray]:
    """Test rows of each cross-validation fold: whole design points when the data mark them
    (``dataset.design``), else rows (:func:`calibrate.fit.kfold_indices`, unchanged).

    Points are shuffled by ``seed`` and dealt, largest first, to the fold with the fewest rows so far,
    so that the folds hold about as many rows each.

    Examples
    --------
    >>> from microbearing.calibrate.data import parse_rows
    >>> d = parse_rows([{"load_N": 0.01, "mu_measured": 0.01}] * 4, fixed={"balls": 4, "speed_m_s": 0.1})
    >>> [f.tolist() for f in folds(replace(d, design=np.array([0, 0, 1, 1])), 2)]
    [[0, 1], [2, 3]]
    """
    if dataset.design is None or np.unique(dataset.design).size < n_folds:
        return kfold_indices(dataset.n_points, n_folds, seed)
    points, counts = np.unique(dataset.design, return_counts=True)
    order = np.random.default_rng(seed).permutation(points.size)
    order = order[np.argsort(-counts[order], kind="stable")]
    sizes = np.zeros(n_folds, dtype=int)
    owner = {}
    for k in order:
        fold = int(np.argmin(sizes))
        owner[points[k]] = fold
        sizes[fold] += counts[k]
    fold_of = np.array([owner[p] for p in dataset.design])
    return [np.flatnonzero(fold_of == f) for f in range(n_folds)]


def lack_of_fit(dataset: Dataset, log_residual: np.ndarray, n_fitted: int,
                keep: np.ndarray | None = None) -> LackOfFit | None:
    """Pure error and the lack-of-fit F-test of a model's log residual over the design points.

    The residual sum of squares splits into the spread of each point's rows about their mean residual
    (pure error, ``rows - points`` degrees of freedom) and the points' mean residuals (lack of fit,
    ``points - n_fitted``); a model that lacks nothing leaves the second no larger than the first allows
    (F). Within-point means of the residual, not of the reading, so that a term varying within a point
    (a drift over the session) is the model's. Clipped rows are left out (their reading is not a value).

    Parameters
    ----------
    dataset : Dataset
        Measurements with ``design`` marked (None: no test).
    log_residual : numpy.ndarray
        ``log(mu_measured / mu_model)`` of every row. [1]
    n_fitted : int
        Values fitted (declared parameters and terms' parameters). [1]
    keep : numpy.ndarray, optional
        Rows to count (e.g. not outliers); default all.

    Returns
    -------
    LackOfFit or None
        None without replicates among the rows kept.

    Examples
    --------
    >>> from microbearing.calibrate.data import parse_rows
    >>> d = parse_rows([{"load_N": 0.01, "mu_measured": 0.01}] * 6, fixed={"balls": 4, "speed_m_s": 0.1})
    >>> d = replace(d, design=np.array([0, 0, 1, 1, 2, 2]))
    >>> lof = lack_of_fit(d, np.array([0.01, -0.01, 0.21, 0.19, -0.2, -0.2]), 1)  # sqrt(4e-4 / 3)
    >>> round(lof.pure_error, 4), lof.lack_of_fit_dof, lof.p < 0.01
    (0.0115, 2, True)
    """
    if dataset.design is None:
        return None
    measured = measured_rows(dataset.censored, dataset.n_points)
    rows = measured if keep is None else measured & keep
    point = np.unique(dataset.design[rows], return_inverse=True)[1].ravel()
    r = np.asarray(log_residual, dtype=float)[rows]
    counts = np.bincount(point)
    m, n = counts.size, r.size
    if n - m < 1 or np.sum(counts > 1) < 1:
        return None
    means = np.bincount(point, weights=r) / counts
    ss_pe = float(np.sum(np.square(r - means[point])))
    ss_lof = float(np.sum(counts * np.square(means)))
    df_pe, df_lof = n - m, m - n_fitted
    f = p = None
    if df_lof > 0 and ss_pe > 0:
        f = (ss_lof / df_lof) / (ss_pe / df_pe)
        p = float(stats.f.sf(f, df_lof, df_pe))
    return LackOfFit(m, int(np.sum(counts > 1)), n, float(np.sqrt(ss_pe / df_pe)), df_pe, max(df_lof, 0),
                     None if f is None else float(f), p, int(np.sum(measured & ~rows)),
                     int(dataset.n_points - np.sum(measured)))


def drift_words(effects: Sequence[Mapping[str, Any]], clock: Mapping[str, str] | None = None) -> list[str]:
    """The instrument's drift or step over the session, from the report's effects (a
    ``measurement_drift`` or ``measurement_step`` term), e.g. ``the instrument drifted +7.6 % over the
    session (run_index 0 to 119) ...`` or ``the instrument's reading stepped +6.1 % at run_index 60 ...``.

    ``clock`` (:attr:`MeasurementSystem.clock`) names the columns read from ISO 8601 times and their start:
    a drift's start and end and a step's place on one are said as the times the user wrote, not in hours.
    """
    out, clock = [], dict(clock or {})
    for effect in effects:
        if effect.get("name") == "measurement_step":
            out.append(_step_words(effect, clock))
        if effect.get("name") != "measurement_drift":
            continue
        d = effect["parameters"]["session_drift_log"]
        sd = effect["parameter_std"]["session_drift_log"]
        c = effect["constants"]
        low, high = np.expm1(d - Z95 * sd), np.expm1(d + Z95 * sd)
        driver = effect["drivers"][0]
        start, end = _at(c["start"], driver, clock), _at(c["end"], driver, clock)
        out.append(f"the instrument drifted {100 * np.expm1(d):+.1f} % over the session "
                   f"({driver} {start} to {end}; 95 % interval "
                   f"{100 * low:+.1f} to {100 * high:+.1f} %): "
                   f"a drift of the reading (measurement system), not of the bearing; the fitted physics is "
                   f"the reading at the session's start")
    return out


def _at(value: float, driver: str, clock: Mapping[str, str]) -> str:
    """A value of an order or time column in the column's own terms: the time the user wrote for a column
    read from ISO 8601 times (``clock``: its start), to the second; the number otherwise."""
    if driver not in clock:
        return f"{value:.6g}"
    start = datetime.fromisoformat(clock[driver])
    return (start + timedelta(seconds=round(3600.0 * float(value)))).isoformat(timespec="seconds")


def _step_words(effect: Mapping[str, Any], clock: Mapping[str, str]) -> str:
    """One ``measurement_step`` in words, its place in the column's own terms."""
    s = effect["parameters"]["step_log"]
    sd = effect["parameter_std"]["step_log"]
    c, driver = effect["constants"], effect["drivers"][0]
    after, before = _at(c["after"], driver, clock), _at(c["before"], driver, clock)
    return (f"the instrument's reading stepped {100 * np.expm1(s):+.1f} % at {driver} {after} "
            f"(after {before}; the place searched over the session; 95 % interval of the step "
            f"{100 * np.expm1(s - Z95 * sd):+.1f} to {100 * np.expm1(s + Z95 * sd):+.1f} %): a step of the "
            f"reading (measurement system), not of the bearing; the fitted physics is the reading before "
            f"the step, and later runs are predicted at the level after it")


def with_censor_scale(dataset: Dataset, fit_parameters: Sequence[str], convention: str,
                      terms: Sequence[Term] = ()) -> Dataset:
    """The data with the scale of their censored likelihood (``censor_scale``, std of log μ [1]): the
    robust scale of the log residual of the declared model and ``terms`` fitted on the measured rows
    alone (the data themselves when nothing is clipped).

    Called first with the declared model, then again with the terms the search chose: the declared
    model's residual also holds every effect it lacks (a humidity meniscus, a run-in), and at that wider
    scale a clipped row's censored residual pulls the model up beyond the clip harder than the likelihood
    of the reading's scatter does (``-2 s² log Phi(r / s)`` grows with ``s`` at every ``r``)."""
    if dataset.censored is None:
        return dataset
    rows = np.flatnonzero(measured_rows(dataset.censored, dataset.n_points))
    plain = replace(dataset, censored=None)
    result = fit(plain, fit_parameters, terms, rows=rows, precise=False, convention=convention)
    return replace(dataset, censor_scale=max(robust_scale(result.residual), 1e-6))

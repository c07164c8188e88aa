"""Where the data are: the joint cloud of the calibration rows, and columns that move together.

**The data cloud.** A box per column calls a point "inside" when each of its values lies in its column's
range, even far from every row (10 mm/s at 70 degC when the lab heated up as it sped up).
:class:`DataCloud` keeps the rows in scaled inputs (each varying column standardized, a positive column
spanning more than a decade by its log; a column counted from zero, such as cycles, by the log of its
values plus its least positive one, so that 0 lies next to the data), one per design point (replicated
measurements at one point, to within :data:`REPLICATE_JITTER`, are one row), and scores a point by its
distance to its k-th nearest row (k = 5). The threshold is split-conformal: the
``ceil((1 - alpha)(n + 1))``-th smallest of the design points' own leave-one-out scores (a new design
point is what the rule is about, and its score is never 0), so that a new point drawn like the data is
flagged with chance about ``alpha`` (:data:`CLOUD_ALPHA`, 2 %) whatever the data's shape. A point given
only some of the columns is scored in those columns alone, against the threshold of the same columns.
Beyond the threshold, the share of the prediction interval no fitted value explains (the scatter and the
discrepancy; the fitted values' share is propagated to the point by the model's form, once) is multiplied
by the ratio of the score to the threshold (the interval widens in proportion to the distance from the data;
a documented rule, not a fitted one: a cross-validation that holds out clusters of rows measures how the
error grows along the data's shape, never across it, and in data whose columns move together the error
off the data comes from which of them acts, not from the distance), through :meth:`DataCloud.widening`,
the one place the rule lives. Where two columns move together, the interval also holds the rivals by
confounding (:mod:`calibrate.rivals`): terms on the column the model does not read that the data lean to
but cannot decide, whose envelope parts from the model where one column is varied without the other.

**Lines along which columns move together.** Where two columns' ranks move together
(|Spearman rho| >= :data:`CONFOUNDED_RHO`), the rows lie near a line in those two scaled columns, and a
point off that line (140 mm/s at 27 degC when the lab heated up as it sped up) is where the data cannot
say which of the two acts; yet in five or more columns its distance to the k-th nearest row may stay
below the threshold. So the score is the larger of the k-NN ratio and the departure from the lines (the
distance from the least-squares line of one scaled column on the other, in units of the rows' own
scatter about it, over its own split-conformal threshold); alpha is shared between the two tests, so a
point drawn like the data is still flagged with chance about alpha. The departure is linear in two
scaled columns: its range over a box of inputs is exact at the box's corners, which the certified
bounds of :mod:`optimize.envelope_bound` use.

**The laws' domains.** A term's law holds for its driver's values in the domain the law declares
(:attr:`physics.effects.Effect.domain`, :attr:`physics.effects.DriftLaw.domain`: relative humidity in
[0, 1) for the Kelvin radius and the menisci, a run-in count n >= 0); :func:`law_domains` gives each
in its column's unit, and
:func:`outside_law_domains` names the columns of a request whose values (numbers, ranges or sets of
values) leave one, so that a route refuses them when they are submitted rather than a job failing later.

**Confounding.** :func:`confounded_pairs` names every pair of varying columns whose ranks move
together (|Spearman rho| >= :data:`CONFOUNDED_RHO`): whatever one of them seems to do, the other
could be doing, and only rows where they part would tell.
"""

from __future__ import annotations

import itertools
import math
import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats
from scipy.spatial import cKDTree

from microbearing import physics
from microbearing.physics.columns import counted_from_zero, outside_range, physical_range, unit_of
from microbearing.physics.effects import Domain

__all__ = ["CLOUD_ALPHA", "CONFOUNDED_RHO", "EXTRAPOLATION_SHARE", "REPLICATE_JITTER", "CloudSpace",
           "DataCloud", "LawDomain", "confounded_pairs", "confounding_words", "edge_trends",
           "extrapolation_allowance", "extrapolation_bound", "law_domains", "outside_law_domains",
           "outside_physical_ranges", "range_slack", "term_trends"]

#: Chance that a new point drawn like the data is flagged outside the cloud. [1]
CLOUD_ALPHA = 0.02
#: Rank correlation beyond which two columns are said to move together. [1]
CONFOUNDED_RHO = 0.9
#: Rows the cloud keeps at most (a random subset of larger data). [1]
MAX_CLOUD_ROWS = 2000
#: Relative difference of a column's values within which two rows are replicates of one design point
#: (measurement jitter: two readings each within 0.1 % of a set point differ by up to 0.2 %; design points
#: 1 % apart stay two). [1]
REPLICATE_JITTER = 3e-3
# Neighbours of the score. [1]
_K = 5


def _distinct(rows: np.ndarray, tolerance: np.ndarray | None = None) -> np.ndarray:
    """The rows with one per design point, in their order (the first of each point kept).

    Rows are replicates of one point when every scaled column differs by at most its ``tolerance``
    (measurement jitter: a speed of 0.05003 m/s is a replicate of 0.05 m/s) from the point's first row.
    Without a tolerance (clouds stored before it), rows that agree to six decimals of every scaled column
    (a millionth of its standard deviation, the resolution clouds were once stored at).
    """
    if tolerance is None:
        _, first = np.unique(np.round(rows, 6), axis=0, return_index=True)
        return rows[np.sort(first)]
    # Rows in one cell of a grid of the tolerance's size are one point (cheap, whatever their number); then
    # each cell's first row takes the other cells' first rows within its tolerance, in order.
    scaled = rows / np.maximum(np.asarray(tolerance, dtype=float), 1e-6)
    _, first = np.unique(np.floor(scaled), axis=0, return_index=True)
    order = np.sort(first)
    tree = cKDTree(scaled[order])
    alone = tree.query_ball_point(scaled[order], 1.0, p=np.inf, return_length=True) == 1
    taken = np.zeros(order.size, dtype=bool)
    keep = alone.copy()
    for i in np.flatnonzero(~alone):
        if not taken[i]:
            keep[i] = True
            taken[tree.query_ball_point(scaled[order[i]], 1.0, p=np.inf)] = True
    return rows[order[keep]]


def _transform(name: str, values: np.ndarray) -> tuple[str, float]:
    """How a column is scaled: ``("log", shift)`` (by ``log(value + shift)``) when its positive values span
    more than a decade, else ``("linear", 0)``.

    The shift is 0 except for a column counted from zero (:func:`physics.columns.counted_from_zero`:
    cycles, time run): there it is the least positive value, so that 0, its first value (a run-in's
    start), lies next to the data (at ``log(shift)``, one ``log 2`` below the least positive row) rather
    than at minus infinity.
    """
    positive = values[values > 0]
    if positive.size == 0 or np.max(positive) <= 10.0 * np.min(positive):
        return "linear", 0.0
    if counted_from_zero(name) and np.min(values) >= 0.0:
        return "log", float(np.min(positive))
    return ("log", 0.0) if np.all(values > 0) else ("linear", 0.0)


#: The extrapolation allowance beyond the data's range in a physics input
#: (:meth:`calibrate.CalibratedModel.extrapolation_ratio`): the interval's scatter share is multiplied
#: by 1 + d / (share x span), d the distance beyond the range and span the range's width, both in the
#: input's log for a positive input (speed, load: 5 mm/s is as far below data at 50 mm/s as 500 mm/s is
#: above), else in its unit: it grows by its own size for every quarter of the data's span beyond them.
#: A documented rule, not a fitted one: data at 50-300 mm/s say nothing of a Stribeck rise below
#: 20 mm/s, and no term on speed that they cannot reject bounds it (an exponential rise below the data
#: has any size), so the interval grows with the distance from them, as it does off the data cloud. [1]
EXTRAPOLATION_SHARE = 0.25
# A positive input's log is taken at no less than this share of the data's least value (a speed of 0
# below data at 50 mm/s is as far as 50 um/s: a finite allowance). [1]
_LOG_FLOOR = 1e-3


def _coordinate(value: np.ndarray, low: np.ndarray, high: np.ndarray, start: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """A physics input's values in the allowance's coordinate (its log when ``low`` > 0, at no less than
    :data:`_LOG_FLOOR` of ``start``, else its unit), and whether it is the log."""
    log = low > 0
    with np.errstate(all="ignore"):
        floor = _LOG_FLOOR * np.where(start > 0, start, high)
        return np.where(log, np.log(np.maximum(value, floor)), value), log


def extrapolation_allowance(value: Any, low: Any, high: Any, rows: int | None = None,
                            trend: Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The extrapolation allowance of values of a physics input whose data spanned [low, high], and the
    side they lie on (-1 below, 0 inside, +1 above); broadcasting.

    Inside the range widened by the domain check's slack (:func:`range_slack`: twice the mean spacing
    of ``rows`` values at each end) the allowance is 0; beyond it, 1 + d / (share x
    span), d the distance beyond the widened end and span = high - low, both in the input's log when
    ``low`` > 0 (a value at or below 0 is taken at :data:`_LOG_FLOOR` of the end), else in its unit;
    share :data:`EXTRAPOLATION_SHARE`. With the ``trend`` the data hint at beyond each end
    (:func:`edge_trends`, in units of the interval's half-width: level and growth per unit of the same
    coordinate at the low end, then at the high end), it grows by ``level + growth x D`` more, D the
    distance beyond the data's end: the departure the residuals trend to there, on top of the rule. A
    trend of eight values also holds the generic terms' slope s and their form's rate k at each end
    (:func:`term_trends`: s, k at the low end, then at the high end, after the four), and the allowance
    grows by ``s (|D - E| + D)`` more, E = expm1(k D) / k (D when k = 0) the term's own change beyond the
    end per unit of s: the distance from where the model's form goes to the far side of the band from
    flat to twice the slope at the end (:func:`band_allowance`). It multiplies the interval's scatter
    share (:meth:`calibrate.CalibratedModel.cloud_ratio`); it never falls with the distance (a box's
    largest and least allowance are at its ends).

    Returns
    -------
    tuple of numpy.ndarray
        The allowance [1] and the side [1].
    """
    value, low, high = (np.asarray(x, dtype=float) for x in (value, low, high))
    slack = range_slack(low, high, rows)
    start, end = low - slack, high + slack
    at, log = _coordinate(value, low, high, start)
    (lo_at, _), (hi_at, _), (start_at, _), (end_at, _) = (_coordinate(x, low, high, start)
                                                          for x in (low, high, start, end))
    with np.errstate(all="ignore"):
        below, above = start_at - at, at - end_at
        span = np.where(log, hi_at - lo_at, high - low)
        d = np.maximum(np.maximum(below, above), 0.0) / (EXTRAPOLATION_SHARE * span)
    d = np.where(np.isfinite(d) & (span > 0), d, 0.0)
    side = np.where(d > 0, np.where(below > 0, -1, 1), 0)
    extra = 0.0
    if trend is not None:
        trend = [float(x) for x in trend] + [0.0] * (8 - len(trend))
        level_low, growth_low, level_high, growth_high, slope_low, rate_low, slope_high, rate_high = trend
        beyond_low, beyond_high = np.maximum(lo_at - at, 0.0), np.maximum(at - hi_at, 0.0)
        extra = np.where(side < 0, level_low + growth_low * beyond_low
                         + slope_low * band_allowance(beyond_low, rate_low),
                         level_high + growth_high * beyond_high
                         + slope_high * band_allowance(beyond_high, rate_high))
    return np.where(d > 0, 1.0 + d + extra, 0.0), side


def band_allowance(distance: Any, rate: float) -> np.ndarray:
    """The departure a generic term's slope leaves open at a distance D beyond the data's end, per unit of
    its slope s there [its coordinate]: ``|D - E| + D``, E = expm1(k D) / k (D when k = 0) the term's own
    change beyond the end per unit of s, its form read as an exponential of rate k in the allowance's
    coordinate (:func:`term_trends`; exact for the generic family: a power law's k is 0 in log, the
    tangent of a quadratic in a positive input's unit has k = -1 below the data and +1 above, in its log).

    The data say the departure's pace at their end, not whether it stops or steepens beyond: the truth may
    go on anywhere from flat to twice that pace, a band from 0 to 2 s D; the model goes on by its form,
    s E. The allowance is the distance from the model to the band's far side, ``max(E, 2 D - E)``: D
    when the form goes on at its end's pace (a power law in log), more where it flattens (2 D - E below
    the data for a tangent in load's unit: 2.0 s at 0.5 mN below data at 2 mN, against 1.4 s for D) or
    steepens (E). Non-decreasing in D (its slope is at least 1 where E < D and e^{k D} > 0 where not).
    """
    distance = np.asarray(distance, dtype=float)
    if abs(rate) < 1e-9:
        return distance
    own = np.expm1(rate * distance) / rate
    return np.abs(distance - own) + distance


def edge_trends(columns: Mapping[str, Any], residual: Any, rows: Any,
                ranges: Mapping[str, tuple[float, float]] | None = None, model: Any = None
                ) -> dict[str, list[float]]:
    """The departure from the model that the data hint at beyond each end of each physics input's range.

    For each input of ``ranges`` (name -> the data's [low, high]) whose ``rows`` (a boolean mask: the
    measured rows that are not outliers) hold at least 8 rows and 4 distinct values, a quadratic in the
    allowance's coordinate (the input's log when low > 0, else its unit) is fitted by least squares to
    the ``residual`` (held-out log of measured over predicted μ), as a generic quadratic term on that
    input would be, and read at each end of the range: its value r and outward slope b there, each with
    its standard error se from the fit. Beyond the end the quadratic goes on along its tangent (as the
    generic term does), and the departure's size at a distance D beyond the end is taken as
    ``|r|' + |b|' D`` with ``|x|' = sqrt(max(x^2 - se^2, 0))``, the part of each coefficient's size its
    noise does not explain (``x^2 - se^2`` estimates the squared true coefficient without bias): on data
    the model fits to the edge this is mostly 0, and it grows where the residuals bend or tilt near the
    end, what the data say of the departure there. Not a bound on any departure: data that are flat to
    their end say nothing of a rise beyond it, which the rule's allowance
    (:func:`extrapolation_allowance`) alone holds.

    With the calibrated ``model`` the residuals are of, ``ranges`` are its ``extrapolation_inputs()`` by
    default, and the departure its generic terms took up (:func:`term_trends`: their slope and form's rate
    at each end) follows each input's four values.

    Returns
    -------
    dict of str to list of float
        name -> [level, growth at the low end, level, growth at the high end]: log μ [1] and log μ per
        unit of the coordinate (per e-fold of a positive input); with a ``model`` whose generic terms are
        on the input, then their slope and rate at each end (:func:`term_trends`).
    """
    residual, rows = np.asarray(residual, dtype=float), np.asarray(rows, dtype=bool)
    out: dict[str, list[float]] = {} if model is None else term_trends(model)
    ranges = model.extrapolation_inputs() if ranges is None else ranges
    for name, (low, high) in ranges.items():
        if name not in columns:
            continue
        x = np.asarray(columns[name], dtype=float)
        keep = rows & np.isfinite(x) & np.isfinite(residual)
        if keep.sum() < 8 or np.unique(x[keep]).size < 4 or not high > low:
            continue
        u, _ = _coordinate(x[keep], np.float64(low), np.float64(high), np.float64(low))
        ends, _ = _coordinate(np.array([low, high], dtype=float), np.float64(low), np.float64(high),
                              np.float64(low))
        middle, half = 0.5 * (ends[0] + ends[1]), 0.5 * (ends[1] - ends[0])
        t = (u - middle) / half
        design = np.stack([np.ones_like(t), t, t * t], axis=1)
        coefficients, *_ = np.linalg.lstsq(design, residual[keep], rcond=None)
        left = residual[keep] - design @ coefficients
        covariance = float(left @ left) / (t.size - 3) * np.linalg.pinv(design.T @ design)
        trend = []
        for edge, outward in ((-1.0, -1.0), (1.0, 1.0)):
            level_row = np.array([1.0, edge, edge * edge])
            slope_row = outward * np.array([0.0, 1.0, 2.0 * edge]) / half
            for row in (level_row, slope_row):
                estimate, variance = float(row @ coefficients), float(row @ covariance @ row)
                trend.append(float(np.sqrt(max(estimate * estimate - variance, 0.0))))
        terms = out.get(name, [0.0] * 4)
        out[name] = [a + b for a, b in zip(trend, terms[:4], strict=True)] + terms[4:]
    return out


def term_trends(model: Any) -> dict[str, list[float]]:
    """The departure from the physics that the model's generic terms take up at each end of each physics
    input's range: their outward slope there in the allowance's coordinate (the input's log when low > 0,
    else its unit), less its noise (``sqrt(max(b^2 - se^2, 0))``, se from the covariance of the ``model``'s
    fitted values then its terms' values, :class:`calibrate.CalibratedModel`; the inputs of its
    ``extrapolation_inputs()``), and the rate k at which their form's change goes on beyond the end, read
    as an exponential in the same coordinate (the ratio of its change over two equal steps out is e^{k h}).

    A generic term (:attr:`physics.effects.Effect.generic`: a polynomial or power law in one column) is a
    fallback, not a law: it takes up a departure the data show, and beyond them goes on by a convention
    (along its tangent in its own coordinate, the column's unit for a quadratic: in load's log it flattens
    below the data, k = -1, and steepens above, k = +1; a power law goes on at its pace, k = 0). The data
    say how fast the departure grows at their end, not whether it stops or steepens beyond: the allowance
    holds it from flat to twice the slope at the end, measured from where the term's form takes the model
    (:func:`band_allowance`). Without this a term that took up the bend inside the data left the residuals
    flat to their end (:func:`edge_trends` 0) while the truth steepened beyond it (a rise exp(-load / 1 mN)
    over data at 2-10 mN, asked at 0.5 mN: coverage 0.04). A named law (a catalogue effect, a drift) goes
    on by its physics, and its parameters' uncertainty is the interval's own.

    Returns
    -------
    dict of str to list of float
        name -> [0, 0, 0, 0, slope at the low end, its rate, slope at the high end, its rate]: the
        residuals' four places of :func:`edge_trends` left 0; slopes in log μ per unit of the coordinate
        (per e-fold of a positive input), rates per unit of the coordinate.
    """
    ranges, covariance = model.extrapolation_inputs(), model.covariance
    parts: dict[str, list[tuple[Any, list[float], slice]]] = {}
    start = len(model.fitted)
    for term, values in model.terms:
        where, start = slice(start, start + len(values)), start + len(values)
        if term.kind == "effect" and term.generic and term.drivers[0] in ranges:
            parts.setdefault(term.drivers[0], []).append((term, list(values), where))
    out: dict[str, list[float]] = {}
    for name, terms in parts.items():
        low, high = (float(x) for x in ranges[name])
        ends, _ = _coordinate(np.array([low, high]), np.float64(low), np.float64(high), np.float64(low))
        step, out_step = 1e-4 * (ends[1] - ends[0]), 1e-2 * (ends[1] - ends[0])
        # the ends, just inside each, then one and two steps beyond each
        inward = np.array([1.0, -1.0])
        coordinate = np.concatenate([ends, ends + step * inward, ends - out_step * inward,
                                     ends - 2.0 * out_step * inward])
        at = np.exp(coordinate) if low > 0 else coordinate

        def log_factor(term: Any, p: Any, at: np.ndarray = at) -> np.ndarray:
            return np.log(term.effect.apply(np.ones(at.size), {term.drivers[0]: at},
                                            dict(zip(term.parameter_names, p, strict=True)),
                                            term.drivers, term.constants))

        slope, variance, total = np.zeros(2), np.zeros(2), np.zeros(at.size)
        for term, values, where in terms:
            # outward slope at each end: the value at the end less the one just inside, per unit; the
            # generic family is linear in its parameters: the slope's gradient is its slope at each unit one
            gradient = np.array([(lambda q: np.array([q[0] - q[2], q[1] - q[3]]) / step)(log_factor(term, e))
                                 for e in np.eye(len(values))])
            slope += gradient.T @ np.asarray(values, dtype=float)
            block = (np.zeros((len(values),) * 2) if covariance is None
                     else np.asarray(covariance, dtype=float)[where, where])
            variance += np.einsum("ie,ij,je->e", gradient, block, gradient)
            total += log_factor(term, values)
        growth = np.sqrt(np.maximum(slope * slope - variance, 0.0))
        with np.errstate(all="ignore"):
            ratio = (total[6:8] - total[4:6]) / (total[4:6] - total[0:2])
            rate = np.where((growth > 0) & (ratio > 0) & np.isfinite(ratio), np.log(ratio) / out_step, 0.0)
        out[name] = [0.0, 0.0, 0.0, 0.0, float(growth[0]), float(rate[0]), float(growth[1]), float(rate[1])]
    return out


def range_slack(low: Any, high: Any, rows: int | None = None) -> np.ndarray:
    """How far beyond a column's range [low, high] a value still lies in the domain [its unit]: a relative
    1e-9 (the data's rounding) plus, with the ``rows`` the range was taken from, twice their mean spacing,
    2 (high - low) / (rows - 1) (a new point drawn like the data lies beyond a sample's extreme with chance
    1/(rows + 1) per column and end); broadcasting."""
    low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    slack = 1e-9 * np.maximum(np.maximum(np.abs(low), np.abs(high)), 1e-300)
    if rows is not None and rows > 1:
        slack = slack + 2.0 * (high - low) / (rows - 1)
    return slack


def extrapolation_bound(ranges: Mapping[str, tuple[float, float]], rows: int | None,
                        low: Mapping[str, Any], high: Mapping[str, Any], shape: tuple[int, ...],
                        lower: bool = False, trends: Mapping[str, Sequence[float]] | None = None
                        ) -> np.ndarray:
    """The largest (``lower``: least) extrapolation allowance over boxes of points [1], largest over the
    inputs of ``ranges`` (name -> the data's [low, high]) that ``low`` gives (a point is a box with
    ``low`` = ``high``; columnar, one box per entry), with each input's ``trends`` (as
    :func:`extrapolation_allowance`'s, by name). The allowance grows with the distance beyond a
    range, so it is largest at one of a box's ends and least at its end nearest the range (0 when the box
    meets the range): exact, not only a bound."""
    ratio = np.zeros(shape)
    for name, (lo, hi) in ranges.items():
        if name not in low:
            continue
        a, b = (np.broadcast_to(np.asarray(p[name], dtype=float), shape) for p in (low, high))
        trend = (trends or {}).get(name)
        ra, side_a = extrapolation_allowance(a, lo, hi, rows, trend)
        # points (low is high): one end
        rb, side_b = (ra, side_a) if low is high else extrapolation_allowance(b, lo, hi, rows, trend)
        if lower:
            meets = (side_a == 0) | (side_b == 0) | (side_a != side_b)
            r = np.where(meets, 0.0, np.minimum(ra, rb))
        else:
            r = np.maximum(ra, rb)
        ratio = np.maximum(ratio, r)
    return ratio


@dataclass(frozen=True)
class CloudSpace:
    """The subspace of some of a cloud's columns in which points giving only those columns are scored.

    Attributes
    ----------
    columns : tuple of str
        The columns, in the cloud's order.
    index : tuple of int
        Their positions among :attr:`DataCloud.columns` (and the columns of :attr:`DataCloud.rows`).
    k : int
        The neighbour whose distance is the score. [1]
    threshold : float
        The split-conformal threshold of that distance, in scaled inputs. [1]
    """

    columns: tuple[str, ...]
    index: tuple[int, ...]
    k: int
    threshold: float


@dataclass
class DataCloud:
    """The calibration rows in scaled inputs, with a conformal threshold of the k-NN distance.

    Attributes
    ----------
    columns : list of str
        The varying numeric columns (physics inputs and conditions).
    transforms : list of str
        ``log`` or ``linear`` per column.
    centre, scale : list of float
        Standardization of each (log) column.
    rows : numpy.ndarray
        The (subset of) distinct rows (design points) in scaled inputs, shape (m, len(columns)).
    alpha : float
        See :data:`CLOUD_ALPHA`. [1]
    shift : list of float or None
        Per column, added before its log (0 but for columns counted from zero); None: all 0.
        [unit of the column]
    tolerance : list of float or None
        Per column, the difference in scaled inputs within which rows are replicates of one design point
        (:data:`REPLICATE_JITTER` of its values); None for clouds stored before it (six decimals). [1]
    """

    columns: list[str]
    transforms: list[str]
    centre: list[float]
    scale: list[float]
    rows: np.ndarray = field(repr=False)
    alpha: float = CLOUD_ALPHA
    shift: list[float] | None = None
    tolerance: list[float] | None = None
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def from_columns(cls, columns: Mapping[str, np.ndarray], seed: int = 0,
                     alpha: float = CLOUD_ALPHA) -> DataCloud | None:
        """The cloud of the data's varying columns (None with fewer than two varying columns or
        too few distinct design points: the per-column ranges say everything)."""
        names, transforms, shifts, centre, scale, scaled, tolerance = [], [], [], [], [], [], []
        for name, values in columns.items():
            v = np.asarray(values, dtype=float)
            if np.unique(v).size < 2:
                continue
            transform, shift = _transform(name, v)
            t = np.log(v + shift) if transform == "log" else v
            names.append(name)
            transforms.append(transform)
            shifts.append(shift)
            centre.append(float(np.mean(t)))
            scale.append(float(np.std(t)))
            scaled.append((t - centre[-1]) / scale[-1])
            jitter = (math.log1p(REPLICATE_JITTER) if transform == "log"
                      else REPLICATE_JITTER * float(np.max(np.abs(v))))
            tolerance.append(float(jitter / scale[-1]))
        if len(names) < 2:
            return None
        # One row per design point: replicates at one point (to within jitter) say nothing about where the
        # data are, and with k or more of them every row's k-th neighbour would be its own twin at distance 0
        # (or at the jitter's). Rows are kept at full precision (JSON keeps every digit of a float), so a
        # design point finds its own row.
        rows = _distinct(np.column_stack(scaled), np.asarray(tolerance))
        if rows.shape[0] < 2 * _K + 2:
            return None
        if rows.shape[0] > MAX_CLOUD_ROWS:
            keep = np.sort(np.random.default_rng(seed).choice(rows.shape[0], MAX_CLOUD_ROWS, replace=False))
            rows = rows[keep]
        return cls(names, transforms, centre, scale, rows, alpha, shifts, tolerance)

    def _scaled_column(self, i: int, values: Any) -> np.ndarray:
        """Values of the cloud's ``i``-th column in its scaled inputs (increasing in the values)."""
        v = np.asarray(values, dtype=float)
        if self.transforms[i] == "log":
            v = np.log(np.clip(v + (self.shift[i] if self.shift else 0.0), 1e-300, None))
        return (v - self.centre[i]) / self.scale[i]

    def _tolerance(self, index: Sequence[int]) -> np.ndarray | None:
        return None if self.tolerance is None else np.asarray(self.tolerance, dtype=float)[list(index)]

    def _space(self, given: Sequence[str]) -> tuple[list[int], cKDTree, float]:
        """Column indices, tree and threshold of the subspace of the given columns."""
        key = tuple(given)
        if key not in self._cache:
            index = [self.columns.index(c) for c in given]
            sub = _distinct(self.rows[:, index], self._tolerance(index))
            tree = cKDTree(sub)
            k = min(_K, sub.shape[0] - 1)
            own = tree.query(sub, k=k + 1)[0][:, -1]  # the k-th neighbour other than the row itself
            n = own.size
            rank = min(math.ceil((1.0 - self._alpha_each(given)) * (n + 1)), n)
            self._cache[key] = (index, tree, float(np.sort(own)[rank - 1]), k)
        index, tree, threshold, _ = self._cache[key]
        return index, tree, threshold

    def _lines(self, given: Sequence[str]) -> tuple[list[tuple[int, int, float, float, float]], float]:
        """The lines along which pairs of the given columns move together, and their threshold.

        For every pair whose ranks move together in the rows (|Spearman rho| >= :data:`CONFOUNDED_RHO`),
        the least-squares line of the second scaled column on the first, ``x_j = a + b x_i``, and the
        scatter ``s`` of the rows about it: ``(i, j, a, b, s)`` with positions in ``given``. A row's
        departure is its largest ``|x_j - a - b x_i| / s`` over the lines; the threshold is the
        split-conformal ``ceil((1 - alpha / 2)(n + 1))``-th smallest of the rows' own departures (the
        k-NN threshold takes the other half of alpha, :meth:`_alpha_each`).
        """
        key = ("lines", tuple(given))
        if key not in self._cache:
            index = [self.columns.index(c) for c in given]
            sub = _distinct(self.rows[:, index], self._tolerance(index))
            lines, departures = [], []
            for p, q in itertools.combinations(range(len(index)), 2):
                rho = stats.spearmanr(sub[:, p], sub[:, q]).statistic
                if not np.isfinite(rho) or abs(rho) < CONFOUNDED_RHO:
                    continue
                b, a = np.polyfit(sub[:, p], sub[:, q], 1)
                residual = sub[:, q] - a - b * sub[:, p]
                spread = max(float(np.std(residual)), 1e-9)
                lines.append((p, q, float(a), float(b), spread))
                departures.append(np.abs(residual) / spread)
            threshold = 0.0
            if lines:
                own = np.max(np.column_stack(departures), axis=1)
                n = own.size
                rank = min(math.ceil((1.0 - self.alpha / 2.0) * (n + 1)), n)
                threshold = max(float(np.sort(own)[rank - 1]), 1e-12)
            self._cache[key] = (lines, threshold)
        return self._cache[key]

    def _alpha_each(self, given: Sequence[str]) -> float:
        """The chance of a flag each test (the k-NN distance, the departure from the lines) is given: alpha
        shared between the two where the given columns have lines, so that a point drawn like the data is
        flagged with chance at most alpha in all."""
        return self.alpha / 2.0 if self._lines(given)[0] else self.alpha

    def _line_ratio(self, given: Sequence[str], lo: np.ndarray, hi: np.ndarray, lower: bool) -> np.ndarray:
        """The departure from the lines over the threshold, bounded over boxes of scaled inputs (rows of
        ``lo`` and ``hi``; a point is a box with lo = hi): its largest value (``lower`` false) or least
        (true). Each departure is linear in two scaled columns, so over a box it lies between its values
        at the box's corners: exact, not only a bound."""
        lines, threshold = self._lines(given)
        ratio = np.zeros(lo.shape[0])
        for p, q, a, b, spread in lines:
            low = lo[:, q] - a - np.where(b > 0, b * hi[:, p], b * lo[:, p])
            high = hi[:, q] - a - np.where(b > 0, b * lo[:, p], b * hi[:, p])
            if lower:
                least = np.where((low <= 0) & (high >= 0), 0.0, np.minimum(np.abs(low), np.abs(high)))
                ratio = np.maximum(ratio, least / spread)
            else:
                ratio = np.maximum(ratio, np.maximum(np.abs(low), np.abs(high)) / spread)
        return ratio / threshold if lines else ratio

    def space(self, columns: Sequence[str]) -> CloudSpace:
        """The subspace of the given columns (in the cloud's order): where they sit, k and the threshold."""
        index, _, threshold = self._space(columns)
        return CloudSpace(tuple(columns), tuple(index), self._cache[tuple(columns)][3], threshold)

    def scaled(self, column: str, values: Any) -> np.ndarray:
        """Values of one of the cloud's columns in its scaled inputs (its log where the cloud takes it,
        standardized) [1]; increasing in the values."""
        return self._scaled_column(self.columns.index(column), values)

    def line_ratio(self, columns: Sequence[str], lo: np.ndarray, hi: np.ndarray,
                   lower: bool = False) -> np.ndarray:
        """The departure from the lines of columns moving together over its threshold [1], at its largest
        (``lower`` false) or least (true) over boxes of scaled inputs (rows of ``lo`` and ``hi``, one
        column per entry of ``columns``; a point is a box with lo = hi). Exact: each departure is linear
        in two scaled columns."""
        return self._line_ratio(columns, lo, hi, lower)

    def score(self, points: Mapping[str, Any], shape: tuple[int, ...]) -> tuple[np.ndarray, list[str]]:
        """Distance to the k-th nearest row over the threshold at each point (> 1: outside), and the
        columns it was measured in (those the points give). [1]"""
        given = [c for c in self.columns if c in points]
        if len(given) < 2:
            return np.zeros(shape), given
        index, tree, threshold = self._space(given)
        k = self._cache[tuple(given)][3]
        x = np.column_stack([self._scaled_column(i, np.broadcast_to(
            np.asarray(points[self.columns[i]], dtype=float), shape).ravel()) for i in index])
        distance = tree.query(x, k=k)[0]
        distance = distance[:, -1] if distance.ndim == 2 else distance
        ratio = np.maximum(distance / max(threshold, 1e-12), self._line_ratio(given, x, x, lower=False))
        return ratio.reshape(shape), given

    def widening(self, ratio: Any) -> np.ndarray:
        """Factor on the prediction interval's scatter share (the noise's and discrepancy's standard
        deviation, :meth:`calibrate.CalibratedModel.predict`) at a distance ratio (:meth:`score`) [1]:
        ``max(ratio, 1)``, 1 inside the cloud.

        The one place the rule lives: :meth:`calibrate.CalibratedModel.predict` applies it, and the
        certified bounds over a box (:mod:`optimize.envelope_bound`) apply it to an upper bound of the
        ratio, which is valid only because the widening is non-decreasing in the ratio.
        """
        return np.maximum(np.asarray(ratio, dtype=float), 1.0)

    def _scaled_boxes(self, low: Mapping[str, Any], high: Mapping[str, Any], shape: tuple[int, ...]
                      ) -> tuple[np.ndarray, np.ndarray, cKDTree, float, int] | None:
        """Boxes of points in the cloud's scaled inputs (each column's transform is increasing, so a box
        maps to a box): their low and high corners, the tree and threshold of the columns ``low`` gives,
        and k; None when fewer than two columns are given or there are no boxes."""
        given = [c for c in self.columns if c in low]
        if len(given) < 2 or int(np.prod(shape)) == 0:
            return None
        index, tree, threshold = self._space(given)
        k = self._cache[tuple(given)][3]

        def scaled(points: Mapping[str, Any]) -> np.ndarray:
            return np.column_stack([
                self._scaled_column(i, np.broadcast_to(np.asarray(points[self.columns[i]], dtype=float),
                                                       shape).ravel()) for i in index])

        a, b = scaled(low), scaled(high)
        return np.minimum(a, b), np.maximum(a, b), tree, threshold, k

    def score_bound(self, low: Mapping[str, Any], high: Mapping[str, Any], shape: tuple[int, ...]
                    ) -> np.ndarray:
        """An upper bound of :meth:`score` over boxes of points [1]: every point whose every column lies
        between its ``low`` and ``high`` value (columnar, one box per entry, shaped ``shape``).

        Each column's transform is increasing (a standardized value or log), so a box maps to a box of
        scaled inputs; for any point x of it, the distance to a row p is at most the distance from p to the
        box's farthest corner, D(p). The k-th smallest distance from x over all rows is at most the k-th
        smallest of D over any k or more rows (each distance at most its D, and a subset's k-th smallest at
        least the whole set's): the rows nearest the box's centre are taken, so that the bound tends to
        the score as the box shrinks. Scored in the columns ``low`` gives, as :meth:`score`.
        """
        boxes = self._scaled_boxes(low, high, shape)
        if boxes is None:
            return np.zeros(shape)
        lo, hi, tree, threshold, k = boxes
        size, rows = lo.shape[0], tree.data
        nearest = min(rows.shape[0], 4 * k)
        _, near = tree.query(0.5 * (lo + hi), k=nearest)
        near = np.asarray(near).reshape(size, nearest)
        p = rows[near]  # (boxes, nearest, columns)
        far = np.maximum(np.abs(lo[:, None, :] - p), np.abs(hi[:, None, :] - p))
        farthest = np.sqrt(np.sum(far * far, axis=2))
        kth = np.partition(farthest, k - 1, axis=1)[:, k - 1]
        # Rounding: the tree's own distances and these differ by a few ulps.
        given = [c for c in self.columns if c in low]
        ratio = np.maximum(kth / max(threshold, 1e-12), self._line_ratio(given, lo, hi, lower=False))
        return (ratio * (1.0 + 1e-12)).reshape(shape)

    def score_lower_bound(self, low: Mapping[str, Any], high: Mapping[str, Any], shape: tuple[int, ...]
                          ) -> np.ndarray:
        """A lower bound of :meth:`score` over boxes of points [1] (as :meth:`score_bound`): for any point x
        of a box, the distance to a row is at least the distance from the row to the box (its nearest
        point), so the k-th smallest distance from x is at least the k-th smallest of those over all rows."""
        boxes = self._scaled_boxes(low, high, shape)
        if boxes is None:
            return np.zeros(shape)
        lo, hi, tree, threshold, k = boxes
        rows = tree.data
        gap = np.maximum(0.0, np.maximum(lo[:, None, :] - rows[None], rows[None] - hi[:, None, :]))
        nearest = np.sqrt(np.sum(gap * gap, axis=2))
        kth = np.partition(nearest, k - 1, axis=1)[:, k - 1]
        given = [c for c in self.columns if c in low]
        ratio = np.maximum(kth / max(threshold, 1e-12), self._line_ratio(given, lo, hi, lower=True))
        return (ratio * (1.0 - 1e-12)).reshape(shape)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready data."""
        return {"columns": list(self.columns), "transforms": list(self.transforms),
                "centre": list(self.centre),
                "scale": list(self.scale), "rows": self.rows.tolist(), "alpha": self.alpha,
                **({"shift": list(self.shift)} if self.shift else {}),
                **({"tolerance": list(self.tolerance)} if self.tolerance is not None else {})}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> DataCloud:
        """Rebuild from :meth:`to_json` data.

        Raises
        ------
        ValueError
            For inconsistent sizes.
        """
        columns = [str(c) for c in data["columns"]]
        rows = np.asarray(data["rows"], dtype=float)
        parts = [data["transforms"], data["centre"], data["scale"],
                 *(data[key] for key in ("shift", "tolerance") if data.get(key) is not None)]
        if rows.ndim != 2 or rows.shape[1] != len(columns) or any(len(p) != len(columns) for p in parts):
            raise ValueError("cloud: rows, transforms, centre, scale, shift and tolerance must have one "
                             "entry per column")
        shift, tolerance = data.get("shift"), data.get("tolerance")
        return cls(columns, [str(t) for t in data["transforms"]], [float(c) for c in data["centre"]],
                   [float(s) for s in data["scale"]], rows, float(data.get("alpha", CLOUD_ALPHA)),
                   None if shift is None else [float(s) for s in shift],
                   None if tolerance is None else [float(t) for t in tolerance])


@dataclass(frozen=True)
class LawDomain:
    """The domain a term's law declares for its driver column.

    Attributes
    ----------
    column : str
        The driver column.
    domain : physics.effects.Domain
        Its values the law holds for, in the column's unit (percent humidity: [0, 100)).
    term : str
        The term, in a few words (its label).
    """

    column: str
    domain: Domain
    term: str


def law_domains(terms: Sequence[Any]) -> list[LawDomain]:
    """The domain every term's law declares for its main driver, in the driver column's unit.

    Parameters
    ----------
    terms : sequence of (Term, values)
        A calibrated model's terms with their fitted values (:attr:`calibrate.CalibratedModel.terms`).

    Returns
    -------
    list of LawDomain
        One per term whose law declares a domain.

    Examples
    --------
    >>> from microbearing.calibrate.candidates import EffectTerm
    >>> meniscus = EffectTerm("humidity_meniscus", ("rh_pct",))
    >>> [(d.column, d.domain.text()) for d in law_domains([(meniscus, [1e-5])])]
    [('rh_pct', '[0, 100)')]
    """
    out = []
    for term, _ in terms:
        law = term.spec if term.kind == "drift" else term.effect
        domain = law.column_domain(term.drivers[0])
        if domain is not None:
            out.append(LawDomain(term.drivers[0], domain, term.label))
    return out


def _numbers(value: Any) -> np.ndarray:
    """Every number of a value, a range (``[low, high]`` or ``{"low", "high"}``) or a set of values."""
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":  # columns of points: no loop over them
        return value.astype(float).ravel()
    if isinstance(value, Mapping):
        value = [value[k] for k in ("low", "high") if k in value] + list(value.get("values", []))
    flat = np.ravel(np.asarray(value, dtype=object))
    return np.asarray([v for v in flat if isinstance(v, numbers.Real) and not isinstance(v, bool)],
                      dtype=float)


def outside_law_domains(terms: Sequence[Any], columns: Mapping[str, Any]) -> dict[str, str]:
    """The columns whose values leave the domain of a term's law, each with a sentence saying so.

    A range is inside when both its ends are (a domain is an interval); text (a group label) is not
    looked at.

    Parameters
    ----------
    terms : sequence of (Term, values)
        A calibrated model's terms (as :func:`law_domains`).
    columns : mapping
        Column name to a number, a list of numbers (a range's ends or a set of values) or
        ``{"low": ..., "high": ...}``, in the columns' units.

    Returns
    -------
    dict of str to str
        Column name -> why it is refused (the values, the domain, the term); empty when all lie inside.

    Examples
    --------
    >>> from microbearing.calibrate.candidates import EffectTerm
    >>> meniscus = EffectTerm("humidity_meniscus", ("rh",))
    >>> outside_law_domains([(meniscus, [1e-5])], {"rh": [30, 70]})  # doctest: +ELLIPSIS
    {'rh': 'values 30, 70 lie outside [0, 1), the domain of the law of humidity_meniscus on rh (in the ...)'}
    """
    out: dict[str, str] = {}
    for law in law_domains(terms):
        if law.column not in columns or law.column in out:
            continue
        values = _numbers(columns[law.column])
        bad = np.unique(values[~law.domain.contains(values)])
        if bad.size:
            shown = ", ".join(f"{v:g}" for v in bad[:3]) + (", ..." if bad.size > 3 else "")
            out[law.column] = (f"value{'s' if bad.size > 1 else ''} {shown} lie{'' if bad.size > 1 else 's'} "
                               f"outside {law.domain.text()}, the domain of the law of {law.term} (in the "
                               f"unit of column {law.column} of the calibration data)")
    return out


def outside_physical_ranges(conditions: Sequence[str], columns: Mapping[str, Any]) -> dict[str, str]:
    """The condition columns whose values leave their quantity's physical range
    (:func:`physics.columns.physical_range`: a time or count run below zero, a fraction above 1), each
    with a sentence saying so; ``columns`` as :func:`outside_law_domains` takes them.

    >>> outside_physical_ranges(["time_min"], {"time_min": [-5, 60], "load_N": 0.01})
    {'time_min': 'value -5 lies outside [0, inf] [min], the physical range of time_min'}
    """
    out: dict[str, str] = {}
    for name in conditions:
        low, high = physical_range(name)
        if name not in columns or (low is None and high is None):
            continue
        detail = outside_range(name, _numbers(columns[name]), low, high, unit_of(name) or "1")
        if detail is not None:
            out[name] = detail
    return out


def confounded_pairs(columns: Mapping[str, np.ndarray], rho: float = CONFOUNDED_RHO) -> list[dict[str, Any]]:
    """Pairs of varying columns whose ranks move together.

    Parameters
    ----------
    columns : mapping of str to numpy.ndarray
        Numeric data columns.
    rho : float
        Least |Spearman rank correlation| reported. [1]

    Returns
    -------
    list of dict
        ``columns`` (the two names), ``rank_correlation`` [1], ``summary`` in words (what would
        separate them).

    Examples
    --------
    >>> x = np.arange(20.0)
    >>> [p["columns"] for p in confounded_pairs({"speed_m_s": x, "temperature_C": 20 + x ** 1.1, "h": x % 3})]
    [['speed_m_s', 'temperature_C']]
    """
    varying = {k: np.asarray(v, dtype=float) for k, v in columns.items() if np.unique(v).size > 2}
    names = list(varying)
    out = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            r = float(stats.spearmanr(varying[a], varying[b])[0])
            if np.isfinite(r) and abs(r) >= rho:
                out.append({"columns": [a, b], "rank_correlation": r,
                            "summary": _pair_words(a, b, r, varying)})
    return out


def _unit(name: str) -> str:
    return f" [{physics.PARAMETERS[name].unit}]" if name in physics.PARAMETERS else ""


def _pair_words(a: str, b: str, r: float, varying: Mapping[str, np.ndarray]) -> str:
    lo_a, hi_a = np.min(varying[a]), np.max(varying[a])
    lo_b, hi_b = np.min(varying[b]), np.max(varying[b])
    together = "rise together" if r > 0 else "move oppositely"
    # The corners the data leave empty: where one is high while the other is low (or both, for r < 0).
    far_b = (hi_b, lo_b) if r > 0 else (lo_b, hi_b)
    return (
        f"{a} and {b} {together} in the data (rank correlation {r:.3f}): an effect of one cannot be told "
        f"from an effect of the other, and a term on either may stand for both. Measurements with {a} near "
        f"{lo_a:.4g}{_unit(a)} and {b} near {far_b[0]:.4g}{_unit(b)}, or {a} near {hi_a:.4g}{_unit(a)} and "
        f"{b} near {far_b[1]:.4g}{_unit(b)} (one varied while the other is held) would separate them"
    )


def confounding_words(pairs: Sequence[Mapping[str, Any]], drivers: Sequence[str]) -> list[str]:
    """One sentence per confounded pair, and per chosen driver that is half of one.

    Parameters
    ----------
    pairs : sequence of dict
        From :func:`confounded_pairs`.
    drivers : sequence of str
        Main driver of every term the calibration added.

    Returns
    -------
    list of str
    """
    words = [p["summary"] for p in pairs]
    for driver in dict.fromkeys(drivers):
        for p in pairs:
            if driver in p["columns"]:
                other = next(c for c in p["columns"] if c != driver)
                words.append(f"the term driven by {driver} may be an effect of {other} instead (they move "
                             f"together in the data, rank correlation {p['rank_correlation']:.3f})")
    return words

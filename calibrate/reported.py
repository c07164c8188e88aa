"""The 95 % interval the service reports over an envelope, now and after proposed runs.

A calibrated model's interval (:meth:`calibrate.CalibratedModel.predict`) is the parameters' share, the
scatter and the GP discrepancy's variance, times the widening off the data: the distance ratio to the
data cloud and the extrapolation allowance beyond a physics input's range
(:meth:`calibrate.CalibratedModel.cloud_ratio`). Runs shrink the first by their information, which is
all an I-optimal design sees, and the widening by where they put the data: 16 runs at two support points
leave an envelope far from five distinct rows as wide as before (issue 33: 3.4-4.8x the half-width of 16
random runs). :class:`ReportedWidth` predicts the interval after runs at candidate points

* fast, for the design's search (:meth:`ReportedWidth.search`): the parameters' variance by rank-one
  updates of the information, the cloud's k-th neighbour distance merged with the runs' (its scaling and
  threshold kept), the ranges extended by the runs;
* exactly as a recalibration on the data plus the runs would bound it (:meth:`ReportedWidth.after`): the
  domain and the data cloud rebuilt with the runs (:meth:`calibrate.domain.DataCloud.from_columns`), the
  fitted values and the scatter unchanged.

With rivals (models a recalibration may keep beside the one it chooses, or choose instead) the service
reports the envelope of their intervals, which is wide where their means part. Each rival is refitted,
linearized (one Gauss-Newton step from its fitted values), to runs that follow the reference model: runs
inside the envelope pin every rival to the reference there, runs only at its far side let them part in
between (issue 33: a plan at 20 % and 90 % RH left water menisci 11 % from the Kelvin law at 70-85 % RH and
the reported interval 2.7x its promise). The search and the promise both read that envelope.

A recalibration keeps a rival only while the runs leave it within two standard errors of the reference
(:meth:`ReportedWidth.gap_z`): its misfit at the runs, and what bending to them costs it on the rows it was
fitted to (:meth:`ReportedWidth.cost_on_taken`). The promise leaves out a rival the runs refute; the search
weighs each rival's interval by the probability that the runs leave it a rival (:func:`survival`), so that
runs which refute a rival shrink the reported interval as surely as runs which pin it to the reference
(``bench/experiments.py``, predict+rivals over 12 data sets x 3 noise draws: truth error 0.0060 -> 0.0045,
half-width 0.0591 -> 0.0586, against a search that counted every rival as kept). Which of the model and
its rivals is true the data taken cannot say: the search averages over them, the promise takes the widest.
"""

from __future__ import annotations

import copy
import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import stats
from scipy.linalg import cho_factor, cho_solve
from scipy.spatial import cKDTree

from .credibility import impossible
from .domain import DataCloud, extrapolation_allowance
from .model import CalibratedModel
from .rivals import RIVAL_SE

__all__ = ["ReportedWidth", "ShapeHedge", "columns_after", "envelope_half_width",
           "expected_envelope_half_width", "impossible_over", "promised_cases", "survival"]

# Exchange passes of the search after its greedy construction at most. [1]
_PASSES = 2
# Runs at one candidate at most in the search (more when the candidates are fewer than the runs). [1]
_MOST_REPLICATES = 2


def envelope_half_width(pieces: Sequence[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Half the width of the envelope of intervals exp(centre ± log half-width) [1], per element."""
    upper = np.maximum.reduce([np.exp(centre + half) for centre, half in pieces])
    lower = np.minimum.reduce([np.exp(centre - half) for centre, half in pieces])
    return 0.5 * (upper - lower)


def survival(z) -> np.ndarray:
    """The probability that a rival whose expected paired z against the reference is ``z`` stays a rival
    (its z, which the runs' scatter moves by about one, at most :data:`calibrate.rivals.RIVAL_SE`) [1]."""
    return stats.norm.cdf(RIVAL_SE - np.asarray(z, dtype=float))


def expected_envelope_half_width(always: Sequence[tuple[np.ndarray, np.ndarray]],
                                 maybe: Sequence[tuple[np.ndarray, np.ndarray]],
                                 kept: Sequence[Any]) -> np.ndarray:
    """The expected :func:`envelope_half_width` [1] of the ``always`` intervals and those of ``maybe``,
    each kept independently with its probability in ``kept`` (arrays broadcasting with the pieces): every
    subset of ``maybe`` weighed by its probability."""
    upper = np.maximum.reduce([np.exp(c + h) for c, h in always])
    lower = np.minimum.reduce([np.exp(c - h) for c, h in always])
    ends = [(np.exp(c + h), np.exp(c - h)) for c, h in maybe]  # each piece's bounds, once
    total = np.zeros(np.broadcast_shapes(upper.shape, *(np.shape(c) for c, _ in maybe)))
    for mask in itertools.product((False, True), repeat=len(maybe)):
        weight, up, low = 1.0, upper, lower
        for keep, p, (top, bottom) in zip(mask, kept, ends, strict=True):
            weight = weight * (p if keep else 1.0 - p)
            if keep:
                up, low = np.maximum(up, top), np.minimum(low, bottom)
        total = total + weight * 0.5 * (up - low)
    return total


def promised_cases(pool: Sequence[ReportedWidth], own: set[str]) -> list[ReportedWidth]:
    """The pool's models the promise of ``predict`` takes in turn as true [1]: all but a generic rival (one
    with a generic term the calibrated model, whose term labels are ``own``, lacks), which a recalibration
    never prefers; it stays a rival in the others' cases (bench/plans_promise.py, load labs 1 and 8: a
    generic linear rival of a power law in load taken as true promised 1.7x what the recalibration
    reported). The whole pool when nothing else is left."""
    cases = [r for r in pool if not any(t.generic for t, _ in r.model.terms if t.label not in own)]
    cases = cases or list(pool)
    # nor a model whose scatter the data refute: one whose residuals spread more than the best case's by
    # more than RIVAL_SE standard errors (bench/plans_promise.py: humidity labs' no-term model, ~1.5x its
    # rivals' scatter, and load labs' drag laws at 2.2-2.4x were taken as true and set the promise)
    best = min(cases, key=lambda r: r.scatter_level)
    return [r for r in cases if r is best or r.scatter_z(best) <= RIVAL_SE]


def columns_after(data: Mapping[str, np.ndarray] | None, runs: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The columns a recalibration on the data and the runs reads (the runs alone without data)."""
    count = max((np.size(v) for v in runs.values()), default=0)
    runs = {k: np.broadcast_to(np.asarray(v, dtype=float), (count,)) for k, v in runs.items()
            if np.asarray(v).dtype.kind in "fiub"}
    if data is None:
        return runs
    return {**runs, **{k: (np.concatenate([np.asarray(v, dtype=float), runs[k]]) if k in runs else v)
                       for k, v in data.items()}}


def impossible_over(model: CalibratedModel, columns: Mapping[str, np.ndarray]) -> bool:
    """Whether a drift of the model, with its fitted values, takes its parameter where the physics does not
    go over the columns (:func:`calibrate.credibility.impossible`)."""
    return any(impossible(term, values, columns, model.fitted, model.fixed) for term, values in model.terms)


def _cloud_values(cloud: DataCloud) -> dict[str, np.ndarray]:
    """The cloud's rows in the columns' own units (its scaling undone)."""
    out = {}
    for i, name in enumerate(cloud.columns):
        t = cloud.rows[:, i] * cloud.scale[i] + cloud.centre[i]
        out[name] = np.exp(t) if cloud.transforms[i] == "log" else t
    return out


@dataclass
class _Fast:
    """What the fast prediction reads: the envelope's base variance and scaled distances."""

    kth: int
    threshold: float
    old: np.ndarray  # (m, k) the k smallest distances from each envelope point to the rows taken
    to_candidates: np.ndarray  # (m, n) distances from each envelope point to each candidate
    lines: np.ndarray  # (m,) the departure ratio from the lines of the data (kept)


class ReportedWidth:
    """The log half-width the service reports over an envelope after runs at candidate points.

    Parameters
    ----------
    response : calibrate.experiments.CalibratedResponse
        The model as a design model (its fixed columns).
    candidates, envelope : mapping of str to numpy.ndarray
        Candidate points of the runs and the envelope's points (columns).
    planned : mapping of str to numpy.ndarray, optional
        Runs already planned (they count as taken).
    level : float
        The interval's probability. [1]
    """

    #: Whether runs that follow another model can refute it as a rival (:meth:`gap_z`).
    refutable = True
    # What runs tell the GP discrepancy (:meth:`_gp_covariances`; None without one): its posterior
    # covariance between the envelope and the candidates then the planned runs, among those, and the
    # variance of a measurement's white noise about it.
    gp_between: np.ndarray | None = None
    gp_among: np.ndarray | None = None
    gp_noise: float = 0.0

    def __init__(self, response: Any, candidates: Mapping[str, np.ndarray],
                 envelope: Mapping[str, np.ndarray], planned: Mapping[str, np.ndarray] | None = None,
                 level: float = 0.95):
        self.model: CalibratedModel = response.model
        self.z = float(stats.norm.isf((1.0 - level) / 2.0))
        self.level = level
        model = self.model
        self.envelope = response.points(envelope)
        self.mu = np.ravel(model(self.envelope))
        m = self.mu.size
        self.c = np.asarray(response.sensitivities(envelope), dtype=float).reshape(m, -1)
        p = self.c.shape[1]
        # What no run changes: the scatter of a measurement and the discrepancy's variance.
        self.other = np.square(np.asarray(response.scatter_sd(envelope), dtype=float))
        if model.noise_std_log:  # the small-sample and tail factor the interval applies to one spread
            self.other = self.other * (model.interval_noise_std_log(level) / float(model.noise_std_log)) ** 2
        self.discrepancy = np.ravel(model.discrepancy_bound(self.envelope, self.envelope, (m,))[2])
        self.other = self.other + self.discrepancy
        # the model's scatter as a recalibration would measure it, over its own (held_out_scaled)
        self.scatter_scale = 1.0
        sigma = np.asarray(response.scatter_sd(candidates), dtype=float)
        g = np.asarray(response.sensitivities(candidates), dtype=float).reshape(sigma.size, p)
        self.b = g / sigma[:, None]
        prior = response.prior_information()
        self.prior = np.zeros((p, p)) if prior is None else np.asarray(prior, dtype=float)
        # the data taken's information alone (the planned runs' is added to the prior below): a refit
        # that moves the parameters by a step pays step' F step on those rows (gap_z)
        self.taken_information = self.prior.copy()
        full = response.points(candidates)
        self.candidates = self._columns(full)
        # log μ and a measurement's scatter at the candidates: what a rival's refit is pulled towards
        self.sigma = sigma
        with np.errstate(all="ignore"):
            self.log_mu_candidates = np.log(np.ravel(model(full)))
        self.planned, full_planned = None, None
        self.planned_b, self.planned_sigma, self.planned_log_mu = np.zeros((0, p)), np.zeros(0), np.zeros(0)
        if planned is not None and len(next(iter(planned.values()), [])):
            self.planned_sigma = np.asarray(response.scatter_sd(planned), dtype=float)
            planned_b = np.asarray(response.sensitivities(planned), dtype=float).reshape(-1, p)
            self.planned_b = planned_b / self.planned_sigma[:, None]
            self.prior = self.prior + self.planned_b.T @ self.planned_b
            full_planned = response.points(planned)
            self.planned = self._columns(full_planned)
            with np.errstate(all="ignore"):
                self.planned_log_mu = np.log(np.ravel(model(full_planned)))
        self.fast = self._fast()
        self._gp_covariances(full, full_planned)
        # a law the envelope would take where the physics does not go is not true there (search)
        with np.errstate(all="ignore"):
            self.possible = not impossible_over(model, self.envelope)

    # ------------------------------------------------------------------------------------------ columns
    def _columns(self, points: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """Every column of the domain and the cloud at the points, as the model reads them."""
        count = max((np.size(v) for v in points.values()), default=1)
        columns = self.model.columns_at(points)
        wanted = set(self.model.domain or {}) | set(self.model.cloud.columns if self.model.cloud else ())
        return {k: np.broadcast_to(np.asarray(columns[k], dtype=float), (count,)).copy()
                for k in wanted if k in columns and np.asarray(columns[k]).dtype.kind in "fiub"}

    def _fast(self) -> _Fast | None:
        """The cloud's scaled distances, or None without a cloud or with a cloud column the runs lack."""
        cloud = self.model.cloud
        env = self._columns(self.envelope)
        if cloud is None or any(c not in self.candidates or c not in env for c in cloud.columns):
            return None
        space = cloud.space(cloud.columns)

        def scaled(columns):
            return np.column_stack([cloud.scaled(c, columns[c]) for c in cloud.columns])

        rows = np.unique(cloud.rows, axis=0)
        if self.planned is not None:
            rows = np.vstack([rows, scaled(self.planned)])
        x_env = scaled(env)
        k = space.k
        old = np.sort(cKDTree(rows).query(x_env, k=k)[0].reshape(x_env.shape[0], -1), axis=1)
        x_cand = scaled(self.candidates)
        to_candidates = np.sqrt(np.maximum(
            np.sum(x_env**2, 1)[:, None] + np.sum(x_cand**2, 1)[None, :] - 2.0 * x_env @ x_cand.T, 0.0))
        lines = cloud.line_ratio(list(cloud.columns), x_env, x_env)
        return _Fast(k, max(space.threshold, 1e-12), old, to_candidates, lines)

    def _gp_covariances(self, candidates: Mapping[str, Any], planned: Mapping[str, Any] | None) -> None:
        """The GP discrepancy's posterior covariances given the data taken [1] between the envelope and the
        candidates (then the planned runs) and among those: a recalibration refits the GP with the runs
        (the hyperparameters kept), and runs near the envelope pin the discrepancy there (bench/
        plans_promise.py, load lab 10: a discrepancy sd of 0.099 over the envelope set the promise while
        the plan's runs were counted as telling nothing of it)."""
        gp, model = self.model.discrepancy, self.model
        if gp is None:
            return
        sources = [(model.discrepancy_columns(candidates), (self.b.shape[0],))]
        if planned is not None:
            sources.append((model.discrepancy_columns(planned), (self.planned_sigma.size,)))
        envelope = model.discrepancy_columns(self.envelope)
        self.gp_between = np.hstack([gp.covariance(envelope, self.mu.shape, *source) for source in sources])
        self.gp_among = np.vstack([np.hstack([gp.covariance(*a, *b) for b in sources]) for a in sources])
        self.gp_noise = gp.noise_variance

    def _gp_after(self, counts: np.ndarray) -> tuple[Any, np.ndarray | None, np.ndarray | None]:
        """What runs at ``counts`` and the planned runs tell the GP discrepancy [1] (Rasmussen & Williams
        eq. 2.24, the runs noisy observations of it, a point's replicates averaged): the drop of its
        variance over the envelope, its posterior covariance between the envelope and each candidate, and
        its variance at each candidate (zero, None, None without a GP)."""
        if self.gp_between is None or self.gp_among is None:
            return 0.0, None, None
        n = self.b.shape[0]
        weights = np.concatenate([np.asarray(counts, dtype=float), np.ones(self.gp_among.shape[0] - n)])
        taken = np.flatnonzero(weights)
        variance = np.diag(self.gp_among)[:n].copy()
        if taken.size == 0:
            return np.zeros(self.mu.size), self.gp_between[:, :n], variance
        factor = cho_factor(self.gp_among[np.ix_(taken, taken)] + np.diag(self.gp_noise / weights[taken]))
        between, among = self.gp_between[:, taken], self.gp_among[taken, :n]
        solved = cho_solve(factor, between.T)  # (taken, m)
        drop = np.einsum("it,ti->i", between, solved)
        covariance = self.gp_between[:, :n] - solved.T @ among
        variance = variance - np.einsum("tj,tj->j", among, cho_solve(factor, among))
        return drop, covariance, np.clip(variance, 0.0, None)

    def _domain_after(self, chosen: np.ndarray, extra: int) -> CalibratedModel:
        """The model with its domain's ranges extended by the chosen candidates (and the planned runs)
        and its rows counted with ``extra`` more."""
        model = self.model
        if model.domain is None:
            return model
        domain = {k: list(v) for k, v in model.domain.items()}
        sources = [{k: v[chosen] for k, v in self.candidates.items()}]
        if self.planned is not None:
            sources.append(self.planned)
        for source in sources:
            for k, v in source.items():
                if k in domain and v.size:
                    domain[k] = [min(domain[k][0], float(v.min())), max(domain[k][1], float(v.max()))]
        rows = None if model.domain_rows is None else model.domain_rows + extra
        return replace(model, domain=domain, domain_rows=rows)

    def _extrapolation(self, chosen: np.ndarray, extra: int, each: bool = False) -> np.ndarray:
        """The extrapolation allowance over the envelope after runs at the chosen candidates (``each``:
        and one more run at each candidate, one column per candidate) [1]."""
        after = self._domain_after(chosen, extra)
        ratio = np.zeros((self.mu.size, self.b.shape[0] if each else 1))
        for name, (lo, hi) in after.extrapolation_inputs().items():
            if name not in self.envelope:
                continue
            value = np.broadcast_to(np.asarray(self.envelope[name], dtype=float), self.mu.shape)[:, None]
            if each and name in self.candidates:
                column = self.candidates[name]
                lo, hi = np.minimum(lo, column)[None, :], np.maximum(hi, column)[None, :]
            ratio = np.maximum(ratio, extrapolation_allowance(value, lo, hi, after.domain_rows)[0])
        return ratio

    def held_out_scaled(self, scale: float) -> ReportedWidth:
        """The same widths with the model's scatter ``scale`` times its own [1]: a rival's scatter is its
        in-sample residual's (:func:`calibrate.experiments.rival_models`), while a recalibration that adds
        its term reports a held-out scatter, larger by about the ratio the calibrated model's own two
        show (:func:`calibrate.experiments.held_out_scale`). For the promise (:meth:`after`); the
        search's hedges keep the in-sample scatter."""
        out = copy.copy(self)
        out.other = (self.other - self.discrepancy) * scale**2 + self.discrepancy
        out.scatter_scale = self.scatter_scale * scale
        return out

    @property
    def scatter_level(self) -> float:
        """The model's scatter of log μ [1] as the promise compares models by it (:meth:`held_out_scaled`)."""
        return float(self.model.noise_std_log or 0.0) * self.scatter_scale

    def scatter_z(self, other: ReportedWidth) -> float:
        """How many standard errors this model's :attr:`scatter_level` lies above ``other``'s [1]: the
        log of their ratio over its standard error, sqrt(sum 1 / (2 (rows - parameters))) (a scatter
        estimated on n - p degrees of freedom has log s of variance about 1 / (2 (n - p))). Zero when
        either model does not say on how many rows it was fitted."""
        dof = [None if w.model.domain_rows is None else w.model.domain_rows - w.c.shape[1]
               for w in (self, other)]
        levels = (self.scatter_level, other.scatter_level)
        if any(d is None or d < 1 for d in dof) or min(levels) <= 0.0:
            return 0.0
        return float(np.log(levels[0] / levels[1]) / np.sqrt(sum(0.5 / d for d in dof)))

    # --------------------------------------------------------------------------------------------- fast
    def _state(self, counts: np.ndarray, gp_drop: Any = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The inverse information, the envelope's parameter variance and its sorted k nearest distances
        to the rows taken and the chosen candidates (``gp_drop``: :meth:`_gp_after`'s first item at
        ``counts``, when the caller has it)."""
        information = self.prior + (self.b * counts[:, None]).T @ self.b
        inverse = np.linalg.pinv(information, hermitian=True)
        if gp_drop is None:
            gp_drop = self._gp_after(counts)[0]
        # the parameters' variance, less what the runs tell the GP discrepancy (its share of ``other``)
        variance = np.einsum("ij,jk,ik->i", self.c, inverse, self.c) - gp_drop
        near = None
        if self.fast is not None:
            chosen = np.flatnonzero(counts)
            near = np.sort(np.hstack([self.fast.old, self.fast.to_candidates[:, chosen]]), axis=1)
            near = near[:, : self.fast.kth]
        return inverse, variance, near

    def _log_halves(self, variance, ratio) -> np.ndarray:
        """Log half-width at each envelope point (rows) [1] of each column of variances and distances.

        Off the data every share is widened by the ratio, the fitted values' too, while the model's own
        interval widens the scatter's and the discrepancy's alone (:meth:`calibrate.CalibratedModel.
        predict`): the promise keeps the wider form, its margin where the runs leave the envelope off
        the data (with the model's form humidity labs 4 and 7 of ``bench/plans_promise.py`` reported 1.42
        and 1.26 times their promise; bench/RESULTS.md, h70)."""
        sigma = np.sqrt(np.clip(variance + self.other[:, None], 0.0, None))
        return self.z * sigma * np.maximum(ratio, 1.0)

    def added_each(self, counts: np.ndarray) -> np.ndarray:
        """Log half-width at each envelope point (rows) after one more run at each candidate (columns) [1]."""
        gp_drop, between, among = self._gp_after(counts)  # once: the state's drop and the gain's terms
        inverse, variance, near = self._state(counts, gp_drop)
        cm = self.c @ inverse  # (m, p)
        u = self.b @ inverse  # (n, p)
        gain = np.square(cm @ self.b.T) / (1.0 + np.sum(u * self.b, axis=1))[None, :]
        if between is not None:  # and what one more run at a candidate tells the GP discrepancy
            gain = gain + np.square(between) / (among + self.gp_noise)[None, :]
        after = variance[:, None] - gain
        ratio = np.zeros_like(after)
        if self.fast is not None:
            e = self.fast.to_candidates
            k = self.fast.kth
            kth = near[:, k - 1][:, None]
            below = near[:, k - 2][:, None] if k > 1 else np.zeros_like(kth)
            new = np.where(e >= kth, kth, np.maximum(below, e))
            new[:, counts > 0] = kth  # a replicate adds no row to the cloud
            ratio = np.maximum(new / self.fast.threshold, self.fast.lines[:, None])
        beyond = self._extrapolation(np.flatnonzero(counts), int(counts.sum()) + 1, each=True)
        ratio = np.maximum(ratio, beyond)
        return self._log_halves(after, ratio)

    def after_fast_each(self, counts: np.ndarray) -> np.ndarray:
        """Log half-width at each envelope point [1] after runs at the candidates (``counts``), fast."""
        _, variance, near = self._state(counts)
        ratio = self._extrapolation(np.flatnonzero(counts), int(counts.sum()))[:, 0]
        if self.fast is not None:
            ratio = np.maximum(ratio, np.maximum(near[:, -1] / self.fast.threshold, self.fast.lines))
        return self._log_halves(variance[:, None], ratio[:, None])[:, 0]

    # ------------------------------------------------------------------------------------------- rivals
    def _pull(self, reference: ReportedWidth, counts: np.ndarray):
        """What runs measured as ``reference`` predicts do to this model's parameters, linearized (one
        Gauss-Newton step of its refit from its fitted values, whose gradient on the data taken is zero):
        the inverse of the information, the scaled misfits at the candidates and at the planned runs,
        and the step [1]."""
        with np.errstate(all="ignore"):
            y = (reference.log_mu_candidates - self.log_mu_candidates) / self.sigma
            y_planned = (reference.planned_log_mu - self.planned_log_mu) / self.planned_sigma
        y = np.where(np.isfinite(y), y, 0.0)
        y_planned = np.where(np.isfinite(y_planned), y_planned, 0.0)
        information = self.prior + (self.b * counts[:, None]).T @ self.b
        inverse = np.linalg.pinv(information, hermitian=True)
        pulled = self.b.T @ (counts * y) + self.planned_b.T @ y_planned
        return inverse, y, y_planned, inverse @ pulled

    def centre_each(self, reference: ReportedWidth, counts: np.ndarray) -> np.ndarray:
        """log μ at each envelope point (rows) after runs at ``counts`` and one more at each candidate
        (columns), this model refitted to measurements that follow ``reference`` [1]: a rival that the
        runs pin where they are taken agrees with the reference there, and parts from it between."""
        inverse, y, _, step = self._pull(reference, counts)
        u = self.b @ inverse  # (n, p)
        factor = (y - self.b @ step) / (1.0 + np.sum(u * self.b, axis=1))  # rank-one update of the step
        return (np.log(self.mu) + self.c @ step)[:, None] + (self.c @ u.T) * factor[None, :]

    def centre_after(self, reference: ReportedWidth, counts: np.ndarray) -> np.ndarray:
        """log μ over the envelope after runs at ``counts``, refitted to measurements that follow
        ``reference`` [1]."""
        return np.log(self.mu) + self.c @ self._pull(reference, counts)[3]

    def centre(self, reference: ReportedWidth, counts: np.ndarray, each: bool) -> np.ndarray:
        """:meth:`centre_each` (``each``: after one more run at each candidate) or :meth:`centre_after`."""
        return self.centre_each(reference, counts) if each else self.centre_after(reference, counts)

    def gap_z(self, reference: ReportedWidth, counts: np.ndarray) -> float:
        """The paired z by which this model, refitted, would lose to ``reference`` on runs at ``counts``
        (and the planned runs) measured as ``reference`` predicts [1]: the calibration keeps a rival
        while the mean of its rows' held-out loss differences stays within :data:`calibrate.rivals.
        RIVAL_SE` standard errors of it. A run missed by d (in scatter units) adds d^2 to the loss on
        average, with variance 4 d^2 from the scatter, and the rows' differences spread by d^4 besides:
        a law missed at a few rows stays a rival however far off it is there (z at most sqrt(rows)).
        The refit's step s away from the fit to the data taken costs it s' F s on those rows (F their
        information), spread over them (variance 4 s' F s): a rival that bends to follow the runs
        loses on the rows it was fitted to."""
        return float(self.gap_z_each(reference, counts, more=False)[0])

    def cost_on_taken(self, reference: ReportedWidth, counts: np.ndarray) -> float:
        """What the refit to runs at ``counts`` measured as ``reference`` predicts adds to this model's loss
        on the rows it was fitted to, in units of its scatter squared [1]: s' F s for the refit's step s
        (linearized) and the information F of those rows."""
        step = self._pull(reference, counts)[3]
        return float(step @ self.taken_information @ step)

    def gap_z_each(self, reference: ReportedWidth, counts: np.ndarray, more: bool = True) -> np.ndarray:
        """:meth:`gap_z` after one more run at each candidate (``more``; else one value, the runs as
        they are) [1], by the rank-one update of the refit's step."""
        inverse, y, y_planned, step = self._pull(reference, counts)
        e = y - self.b @ step
        e_planned = y_planned - self.planned_b @ step
        taken = self.taken_information
        if not more:
            d2 = np.concatenate([np.repeat(np.square(e), counts.astype(int)), np.square(e_planned)])
            paid = float(step @ taken @ step)  # cost_on_taken, from the step already pulled
            spread = float(np.sqrt(np.sum(4.0 * d2 + np.square(d2)) + 4.0 * paid))
            return np.array([(float(np.sum(d2)) + paid) / spread if spread > 0 else 0.0])
        u = self.b @ inverse  # (n, p): the step's change per unit misfit of one more run there
        leverage = np.einsum("ij,ij->i", self.b, u)
        f = e / (1.0 + leverage)  # the step moves by u_j f_j with one more run at candidate j
        own = np.square(e - leverage * f)  # the new run's own misfit after it
        # the misfits after one more run at j of the candidates already run (rows), only those: the
        # others count zero times (n x taken, not n x n: most of the search's time on large pools)
        taken_at = np.flatnonzero(counts)
        r2 = np.square(e[taken_at, None] - (self.b[taken_at] @ u.T) * f[None, :])
        weights = counts[taken_at]
        total = weights @ r2 + own
        spread = weights @ (4.0 * r2 + np.square(r2)) + 4.0 * own + np.square(own)
        if e_planned.size:
            rp = np.square(e_planned[:, None] - (self.planned_b @ u.T) * f[None, :])
            total, spread = total + rp.sum(0), spread + (4.0 * rp + np.square(rp)).sum(0)
        fs, fu = taken @ step, u @ taken
        paid = float(step @ fs) + 2.0 * f * (u @ fs) + np.square(f) * np.sum(fu * u, axis=1)
        total, spread = total + paid, spread + 4.0 * paid
        with np.errstate(all="ignore"):
            return np.where(spread > 0, total / np.sqrt(spread), 0.0)

    def _expected_hull(self, counts: np.ndarray, rivals: Sequence[ReportedWidth], each: bool):
        """The mean over the envelope of the expected half-width the service reports after the runs [1]
        (``each``: one value per candidate, after one more run there), averaged over which of this model
        and its refutable ``rivals`` is true (the data taken cannot tell them apart: equal weights; one that
        takes a parameter where the physics does not go over the envelope is never true). Under each, that
        model's interval is reported, beside it those the runs cannot refute (the shape hedges and the
        models impossible over the envelope, refitted to runs that follow the true one: a refit to runs
        there may bring them back into range), and each other model's, refitted likewise, with the
        probability that the runs leave it a rival (:func:`survival` of its :meth:`gap_z`)."""
        refutable = [self, *(r for r in rivals if r.refutable)]
        models = [m for m in refutable if m.possible] or refutable
        pinned = [r for r in rivals if not r.refutable] + [m for m in refutable if m not in models]
        width = {id(m): m.added_each(counts) if each else m.after_fast_each(counts)
                 for m in [*models, *pinned]}
        total = 0.0
        for truth in models:
            own = np.log(truth.mu)[:, None] if each else np.log(truth.mu)
            always = [(own, width[id(truth)]),
                      *((m.centre(truth, counts, each), width[id(m)]) for m in pinned)]
            others = [m for m in models if m is not truth]
            maybe = [(m.centre(truth, counts, each), width[id(m)]) for m in others]
            kept = [survival(m.gap_z_each(truth, counts))[None, :] if each
                    else survival(m.gap_z(truth, counts)) for m in others]
            total = total + np.mean(expected_envelope_half_width(always, maybe, kept), axis=0)
        return total / len(models)

    def _added(self, counts: np.ndarray, rivals: Sequence[ReportedWidth]) -> np.ndarray:
        """:meth:`_expected_hull` after one more run at each candidate [1]."""
        return self._expected_hull(counts, rivals, each=True)

    def mean_after_fast(self, counts: np.ndarray, rivals: Sequence[ReportedWidth] = ()) -> float:
        """:meth:`_expected_hull` after runs at the candidates (``counts``), fast [1]."""
        return float(self._expected_hull(counts, rivals, each=False))

    def search(self, start: np.ndarray, rivals: Sequence[ReportedWidth] = ()) -> np.ndarray:
        """Runs (counts per candidate, as many as ``start``) that make the reported half-width over the
        envelope small: built greedily run by run (the candidate that shrinks the mean half-width most),
        then improved by moving single runs; ``start`` (an I-optimal design) when that is no better.
        With ``rivals`` (the rivals' widths over the same candidates and envelope) the half-width at
        each point is the expected envelope of the model's and theirs (:meth:`_expected_hull`): the runs
        hedge against the terms a recalibration may add, or refute them, whichever model is true."""
        runs = int(start.sum())
        # Replicates at most per candidate: the calibration holds a design point's replicates out
        # together, so runs piled on a few points leave its held-out scatter to extrapolations.
        most = max(_MOST_REPLICATES, -(-runs // start.size))
        counts = np.zeros_like(start)
        for _ in range(runs):
            counts[int(np.argmin(np.where(counts >= most, np.inf, self._added(counts, rivals))))] += 1
        best = self.mean_after_fast(counts, rivals)
        for _ in range(_PASSES):
            moved = False
            for source in np.repeat(np.arange(counts.size), counts):
                if counts[source] == 0:
                    continue
                counts[source] -= 1
                values = np.where(counts >= most, np.inf, self._added(counts, rivals))
                target = int(np.argmin(values))
                if values[target] < best * (1.0 - 1e-9) and target != source:
                    counts[target] += 1
                    best, moved = float(values[target]), True
                else:
                    counts[source] += 1
            if not moved:
                break
        return counts if best <= self.mean_after_fast(start, rivals) or start.max() > most else start.copy()

    # -------------------------------------------------------------------------------------------- exact
    def interval_now(self) -> tuple[np.ndarray, np.ndarray]:
        """The interval the service reports over the envelope now, (mu_lower, mu_upper) [1] of
        :meth:`calibrate.CalibratedModel.predict` (the rivals' envelope included): where μ may lie."""
        with np.errstate(all="ignore"):
            prediction = self.model.predict(self.envelope, self.level)
        return np.ravel(prediction.mu_lower), np.ravel(prediction.mu_upper)

    def now(self) -> np.ndarray:
        """The half-width the service reports over the envelope now [1]: (mu_upper - mu_lower) / 2 of
        :meth:`interval_now`."""
        lower, upper = self.interval_now()
        return 0.5 * (upper - lower)

    def log_half_after(self, counts: np.ndarray) -> np.ndarray:
        """This model's log half-width over the envelope after the runs [1], as a recalibration on the
        data plus the runs would bound it: the domain and the data cloud rebuilt with them, the
        information increased by theirs (fitted values and scatter unchanged)."""
        chosen = np.flatnonzero(counts)
        model = self._domain_after(chosen, int(counts.sum()))
        cloud = model.cloud
        if cloud is not None and self.fast is not None:
            values = _cloud_values(cloud)
            added = [{c: self.candidates[c][chosen] for c in cloud.columns}]
            if self.planned is not None:
                added.append({c: self.planned[c] for c in cloud.columns})
            joined = {c: np.concatenate([values[c], *(a[c] for a in added)]) for c in cloud.columns}
            model = replace(model, cloud=DataCloud.from_columns(joined, alpha=cloud.alpha))
        _, variance, _ = self._state(counts)
        ratio = np.ravel(model.cloud_ratio(self.envelope, self.mu.shape))
        sigma = np.sqrt(np.clip(variance + self.other, 0.0, None))
        return self.z * sigma * np.ravel(model.widening(ratio))

    def after(self, counts: np.ndarray, rivals: Sequence[ReportedWidth] = ()) -> np.ndarray:
        """The half-width the service would report over the envelope after the runs [1]: this model's
        interval (:meth:`log_half_after`) and, with ``rivals``, the envelope of theirs, each refitted to
        runs that follow this model (:meth:`centre_after`) as a recalibration that keeps them would; a
        rival the runs refute (:meth:`gap_z` beyond :data:`calibrate.rivals.RIVAL_SE`) is left out, as
        the recalibration drops it."""
        pieces = [(np.log(self.mu), self.log_half_after(counts))]
        pieces += [(r.centre_after(self, counts), r.log_half_after(counts)) for r in rivals
                   if r.gap_z(self, counts) <= RIVAL_SE]
        return envelope_half_width(pieces)


class ShapeHedge(ReportedWidth):
    """The width of a model with a law the data have not seen added at one value of its shape
    (:func:`calibrate.shape_hedges.shape_hedges`), centred on the reference model: its values are
    unknown, so its μ says nothing, while its interval after the runs is what a recalibration that adds the
    law reports (the law's parameters pinned, or not, by where the runs are). Never refuted by runs that
    follow the reference: the law is hedged whatever they show."""

    refutable = False

    def centre_each(self, reference: ReportedWidth, counts: np.ndarray) -> np.ndarray:
        return np.repeat(np.log(reference.mu)[:, None], self.b.shape[0], axis=1)

    def centre_after(self, reference: ReportedWidth, counts: np.ndarray) -> np.ndarray:
        return np.log(reference.mu)

    def gap_z(self, reference: ReportedWidth, counts: np.ndarray) -> float:
        return 0.0

    def gap_z_each(self, reference: ReportedWidth, counts: np.ndarray, more: bool = True) -> np.ndarray:
        return np.zeros(self.b.shape[0] if more else 1)


def promise(reported: Sequence[ReportedWidth], counts: np.ndarray, held_out_scale: float,
            taken: Mapping[str, np.ndarray], own: set[str]) -> dict[str, dict[str, float]]:
    """A proposal's figures of the reported interval over the envelope, from ``reported`` (the calibrated
    model's, then its rivals' and shape hedges') for runs at ``counts``: the half-width reported now and
    expected after a recalibration, in μ's units and as a fraction of μ, and the span of the latter times
    today's interval [1] (``taken``: the data's columns with the runs'; ``own``: the model's term labels)."""
    # after the runs: the interval of the model that is true among the calibrated one and the hedged
    # rivals, enveloping the others refitted to runs that follow it while they stay rivals
    shapes = [r for r in reported[1:] if isinstance(r, ShapeHedge)]  # hedged whatever the runs show
    pool = [reported[0], *(r.held_out_scaled(held_out_scale) for r in reported[1:]
                           if not isinstance(r, ShapeHedge))]
    # a law the runs would take where the physics does not go is not chosen nor kept (a linear drift
    # run on to ten times its cycles takes mu_pivot below zero)
    pool = [r for r in pool if not impossible_over(r.model, taken)] or pool
    # the data taken cannot tell the pool's models apart: each in turn is true (a generic rival
    # aside), its interval reported with the others' its runs leave rivals
    cases = promised_cases(pool, own)
    afters = [truth.after(counts, [*(r for r in pool if r is not truth), *shapes]) for truth in cases]
    lower_now, upper_now = reported[0].interval_now()
    now = 0.5 * (upper_now - lower_now)
    # relative, a fraction of μ (a rise the runs find is no width): the widest case's own (its half-width
    # over its μ), not the widest half-width over the lowest μ of another case
    widest, mus = np.argmax(afters, axis=0), np.array([t.mu for t in cases])
    own_relative = np.array(afters) / mus
    relative = np.take_along_axis(own_relative, widest[None], axis=0)[0]
    out = {key: {"mean": float(np.mean(values)), "max": float(np.max(values))}
           for key, values in (("reported_half_width_now", now),
                               ("reported_half_width_after", np.max(afters, axis=0)),
                               ("reported_relative_half_width_now", now / reported[0].mu),
                               ("reported_relative_half_width_after", relative))}
    # the half-width after in μ's units is the relative one times μ where the recalibration finds it:
    # anywhere in today's interval (off the data in a load or speed the runs reach, μ moved 1.4-1.6x) or at
    # a case's μ (a law the data lean to that the interval does not hold: Kelvin menisci at 70-85 % RH)
    out["reported_half_width_after_span"] = {
        "low": float(np.mean(relative * np.minimum(lower_now, mus.min(axis=0)))),
        "high": float(np.mean(relative * np.maximum(upper_now, mus.max(axis=0))))}
    return out

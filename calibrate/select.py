"""Step 4 of the pipeline: choose the terms the data need, by forward selection and cross-validation.

:func:`forward_select` starts from the declared model and, step by step, scores
every candidate term (:func:`calibrate.candidates.candidate_terms`) by k-fold
cross-validation with the same folds for all:

1. **Screening**: each candidate is fitted on all rows on top of the current
   model frozen there (:class:`calibrate.candidates.FrozenBase`: a drift, and a
   shift of the declared parameters, act to first order) and ranked by its
   in-sample score.
2. **Joint refit**: the best screened candidates (overall and among the named
   ones) are refitted on each training fold with the declared parameters and the
   terms already chosen, and scored on the held-out rows.

Every held-out residual is scored by Huber's loss at the robust scale of the
current model (:func:`calibrate.fit.huber_loss`), so that gross outliers weigh
like a few ordinary rows. A candidate counts only if it beats the current model
on both

* a BIC-like score ``n log(mean loss) + p log(n)`` (``p`` = all fitted parameters), and
* a paired test of the per-row held-out losses, ``z > max(z_threshold, z_family)``,
  where ``z_family`` keeps the chance that any of the m candidates of a step passes
  on noise alone at :data:`FAMILY_ALPHA` (:func:`max_t_threshold`: Westfall and
  Young's max-T, the candidates' paired z's flipped by the same random signs),

and, when ``mu_measured_std`` is given, only while the current model's residual is
not consistent with that noise (chi-square test at 1 %).

The paired test takes its spread from the differences themselves, so that a few
gross outliers cannot pass for an effect; the price is that an effect carried by
m rows alone (a breakaway rise below a Stribeck speed that few rows reach) cannot
reach a z above about √m, however large it is on them: it is found only when
about z² rows show it. The family-wise threshold is not a Bonferroni bound over the
m candidates (Φ⁻¹(1 - α/m), 3.58 for 60), which holds whatever their dependence and
is tight only for independent ones: they are drifts of the same few parameters and
forms over the same columns, so their paired z's move together, and the max-T
threshold, which reads their correlation from the screening's per-row gains, is
lower at the same family-wise error (3.26-3.47 for the 59 candidates of the
benchmark's 160-200-row data sets). Among the candidates that count, the lowest
score wins, except that a named mechanism whose loss lies within one standard
error of the winner's is preferred to a generic term (a
catalogue effect first, then the parameter drift that needs the smallest change
of its parameter over the data). The shortlist of joint refits holds the best
screened candidates overall, among catalogue effects and among drifts, and every
named one that screens within one standard error of the best. The
winner is added, everything refitted, and the search repeated on the remaining
candidates until none counts or :data:`MAX_TERMS` are in.

Choosing the best of many candidates on the same folds that score them makes
the winner's CV error optimistic (selection bias). :func:`nested_cross_validate`
therefore repeats the whole forward selection inside each training fold and
predicts each outer test fold with what that selection chose: an honest held-out
error of the procedure, and how often it chose the same terms.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .candidates import Term
from .censored import measured_rows
from .data import Dataset
from .fit import FitResult, fit, predict_mu
from .groups import why_not_fitted
from .measurement import folds as design_folds
from .scatter import ScatterModel, fit_scatter
from .scores import (
    SIGN_FLIPS,
    CandidateScore,
    ModelCV,
    Step,
    close_calls,
    count_parameters,
    cross_validate,
    max_t_threshold,
    noise_test,
    preferred,
    usable,
)
from .search import (
    FAMILY_ALPHA,
    MAX_SEARCH_ROWS,
    MAX_TERMS,
    SCATTER_ROUNDS,
    SearchOptions,
    search_step,
    shifted,
)

__all__ = [
    "FAMILY_ALPHA",
    "MAX_SEARCH_ROWS",
    "MAX_TERMS",
    "SCATTER_ROUNDS",
    "SIGN_FLIPS",
    "CandidateScore",
    "ModelCV",
    "NestedValidation",
    "SearchOptions",
    "Selection",
    "Step",
    "WithinGroups",
    "between_groups",
    "cross_validate",
    "forward_select",
    "held_out_of_chosen",
    "max_t_threshold",
    "nested_cross_validate",
    "noise_test",
    "preferred",
    "scatter_weighted",
    "held_out_within_groups",
    "search_data",
    "varying_columns",
    "with_search_groups",
]

#: Candidates per step whose scores the report keeps. [1]
REPORTED_CANDIDATES = 15


@dataclass(frozen=True)
class Selection:
    """Outcome of :func:`forward_select`.

    Attributes
    ----------
    terms : tuple of Term
        Terms chosen, in order.
    steps : list of Step
        Every step, the last one the step that stopped (unless :data:`MAX_TERMS` were added).
    model : ModelCV
        The final model cross-validated on the search rows.
    scale : float
        Robust scale of the final model's weighted log residual on the search rows. [1]
    rows : numpy.ndarray
        Rows (0-based) the search ran on: all, or a random subset of :data:`MAX_SEARCH_ROWS`.
    reason : str
        The decision in words.
    scatter : ScatterModel or None
        The scatter model that weighted the search (:func:`scatter_weighted`; its spreads are standard
        deviations of log μ [1]), None when it ran unweighted (one scatter everywhere, or
        ``mu_measured_std`` declared). ``model`` and ``scale`` are on the weighted rows.
    """

    terms: tuple[Term, ...]
    steps: list[Step]
    model: ModelCV
    scale: float
    rows: np.ndarray = field(repr=False)
    reason: str = ""
    scatter: ScatterModel | None = None



def search_rows(n_points: int, max_rows: int, seed: int) -> np.ndarray:
    """Rows the search runs on: all of them, or a sorted random subset of ``max_rows``."""
    if n_points <= max_rows:
        return np.arange(n_points)
    return np.sort(np.random.default_rng(seed).choice(n_points, max_rows, replace=False))


def search_data(dataset: Dataset, rows: np.ndarray) -> Dataset:
    """The rows the search ran on (:func:`search_rows`, :attr:`Selection.rows`) as a dataset: the data
    themselves when they are all of them."""
    return dataset if rows.size == dataset.n_points else dataset.subset(rows)


def with_search_groups(dataset: Dataset) -> Dataset:
    """The data with each row's group code (:attr:`Dataset.search_groups`) when factor columns label groups
    whose spread :mod:`calibrate.groups` fits: the fits the search scores then give every group its own
    level of log μ (profiled out, the population's level kept by the declared parameters), so that the
    groups' offsets are not left in the residual the candidates are judged on, and a held-out row is
    predicted with its group's level from the training rows. Several such factors: their combinations,
    when those still hold two rows a group, else the first. The data themselves without any, or with a
    clipped reading (whose censored residual a level cannot shift), or with a condition column set per
    group (:func:`between_groups`: a coating or a build parameter per specimen, whose effect a level per
    group would absorb, so the search judges it on the groups' differences as without levels)."""
    if dataset.censored is not None or dataset.search_groups is not None:
        return dataset
    eligible = [np.asarray(dataset.factors[name]).astype(str) for name in sorted(dataset.factors)
                if why_not_fitted(dataset.factors[name]) is None]
    if not eligible:
        return dataset
    labels = np.array(["\x1f".join(cell) for cell in zip(*eligible, strict=True)])
    if why_not_fitted(labels) is not None:
        labels = eligible[0]
    codes = np.unique(labels, return_inverse=True)[1].astype(int)
    if between_groups(dataset.conditions, codes):
        return dataset
    return replace(dataset, search_groups=codes)


def between_groups(columns: Mapping[str, Any], codes: np.ndarray) -> tuple[str, ...]:
    """The columns that vary between the groups of ``codes`` and not within any: what only the groups'
    differences can tell of.

    >>> between_groups({"coated": np.array([0, 0, 1, 1]), "RH": np.array([0.2, 0.4, 0.2, 0.4])},
    ...                np.array([0, 0, 1, 1]))
    ('coated',)
    """
    order = np.argsort(codes, kind="stable")
    cuts = np.flatnonzero(np.diff(codes[order])) + 1  # where one group's sorted rows end
    found = []
    for name, values in columns.items():
        x = np.asarray(values)
        if x.dtype.kind not in "biuf" or np.unique(x).size < 2:
            continue
        if all(np.unique(part).size == 1 for part in np.split(x[order], cuts)):
            found.append(name)
    return tuple(found)


def varying_columns(dataset: Dataset) -> dict[str, np.ndarray]:
    """Numeric columns (physics inputs and conditions) that vary in the data: what a scatter model may
    depend on."""
    return {k: v for k, v in dataset.columns().items() if v.dtype != bool and np.unique(v).size > 1}


def scatter_weighted(dataset: Dataset, scatter: ScatterModel | None) -> Dataset:
    """The data with every row weighted by the scatter model's local spread.

    Each row's ``mu_measured_std`` becomes ``mu_measured`` times the scatter model's standard deviation
    of log μ there, so that a weighted log residual (:func:`calibrate.fit.weighted_log_residual`)
    counts in units of its own row's scatter: Huber's loss, the scores and the paired z's of the
    selection then judge a row of 8 % scatter by 8 % and a row of 1 % by 1 %. The data themselves
    when ``scatter`` is None or constant (one weight for all changes nothing), or when the data
    declare ``mu_measured_std`` (which weighs the rows already).

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    scatter : ScatterModel or None
        The scatter model (:mod:`calibrate.scatter`).

    Returns
    -------
    Dataset

    Examples
    --------
    >>> from microbearing.calibrate.data import parse_rows
    >>> rows = [{"balls": 4, "load_N": 0.01, "speed_m_s": v, "mu_measured": 0.2} for v in (0.01, 0.1)]
    >>> step = ScatterModel("step", "speed_m_s", [float(np.log(0.1)), float(np.log(0.01))], 0.05)
    >>> scatter_weighted(parse_rows(rows), step).mu_measured_std.round(4).tolist()
    [0.02, 0.002]
    """
    if scatter is None or scatter.kind == "constant" or dataset.mu_measured_std is not None:
        return dataset
    local = scatter.std_log(dataset.columns(), dataset.mu_measured.shape)
    return replace(dataset, mu_measured_std=dataset.mu_measured * local)


def selection_scatter(dataset: Dataset, model: ModelCV, folds: int, seed: int) -> ScatterModel | None:
    """The scatter model (:func:`calibrate.scatter.fit_scatter`) of a model's held-out log residual, or
    None when the data declare ``mu_measured_std``, no column varies, or a row has no held-out
    prediction."""
    if dataset.mu_measured_std is not None:
        return None
    return _held_out_scatter(dataset, model.oof_mu, folds, seed)


def _held_out_scatter(dataset: Dataset, oof_mu: np.ndarray, folds: int, seed: int) -> ScatterModel | None:
    """The scatter model of the held-out log residual against ``oof_mu``, or None when no column varies
    or a row has no held-out prediction."""
    columns = varying_columns(dataset)
    if not usable(oof_mu) or not columns:
        return None
    residual = np.log(dataset.mu_measured / oof_mu)
    rows = measured_rows(dataset.censored, dataset.n_points)  # a clipped reading's residual is not scatter
    return fit_scatter({k: v[rows] for k, v in columns.items()}, residual[rows],
                       min(folds, int(rows.sum())), seed)


def _form(scatter: ScatterModel | None) -> tuple[str, str | None]:
    if scatter is None or scatter.kind == "constant":
        return ("constant", None)
    return (scatter.kind, scatter.column)



def forward_select(
    dataset: Dataset,
    fit_parameters: Sequence[str] = (),
    folds: int = 5,
    seed: int = 0,
    options: SearchOptions | None = None,
    progress: Callable[[float], None] | None = None,
    initial_scatter: ScatterModel | None = None,
) -> Selection:
    """Add terms to the declared model one at a time while cross-validation shows more than noise.

    **Weighted by the scatter.** Where the scatter of the measurements depends on the inputs (stick-slip
    at low speed, a spread that grows with the load), an unweighted search lets the rows of large
    scatter speak as loudly as the quiet ones: their noise then passes for an effect, and a term that
    follows it can win. So the search is repeated, up to ``options.scatter_rounds`` times, weighted by the
    scatter model (:mod:`calibrate.scatter`) of the previous search's model: the first search is
    unweighted; the scatter model of its held-out log residual is fitted (constant unless the
    permutation test rejects one spread everywhere, at :data:`calibrate.scatter.SCATTER_ALPHA`); when
    it is not constant the search runs again with every row weighted by its local scatter
    (:func:`scatter_weighted`), and so on until the scatter model keeps its form (kind and column). The
    scatter is read from the selected model's residual, not from the declared model's: an effect the
    declared model misses leaves residuals that grow where it acts, which a scatter model would take
    for scatter and weigh down, hiding the very effect. Weighted, every part of the search sees the
    local scatter: Huber's loss and its robust scale, the screening and the joint refits, the scores,
    the paired z's and the family-wise threshold, so a row is an outlier against its own scatter. With
    ``mu_measured_std`` declared the rows are weighted by it and the search runs once.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    fit_parameters : sequence of str
        Declared physics parameters, refitted with every candidate.
    folds : int
        Cross-validation folds. [1]
    seed : int
        Seed of the fold shuffle and of the search subset.
    options : SearchOptions, optional
        The paired z's threshold, family-wise chance, joint refits, most terms and rows, convention and
        scatter rounds (default: :class:`SearchOptions`'s defaults).
    progress : callable, optional
        Called with the fraction done, 0..1.
    initial_scatter : ScatterModel, optional
        Weights of the first search instead of none (:func:`nested_cross_validate` gives each fold the
        scatter that weighted the search on all rows, which saves the fold an unweighted search and a
        scatter model when its own residual confirms it; when not, the fold's unweighted search
        stands, as on all rows).

    A weighted search is kept only when the scatter model of its own held-out residual has the form
    (kind and column) of the one that weighted it (its coefficients are then those read before it).
    When that residual shows one scatter everywhere instead, or the rounds run out, the unweighted
    search stands: the scatter that weighted it was likely an effect the unweighted search missed
    (a run-in on 24 rows makes the first cycles' residuals large), and the words say so.

    Returns
    -------
    Selection
    """
    options = options or SearchOptions()
    reached = [0.0]

    def report(fraction: float) -> None:  # monotone, whatever order the searches run in
        if fraction > reached[0] and progress is not None:
            reached[0] = fraction
            progress(fraction)

    rows = search_rows(dataset.n_points, options.max_rows, seed)
    data = with_search_groups(search_data(dataset, rows))
    fold_rows = design_folds(data, folds, seed)  # a design point's replicates in one fold
    declared_noise = data.mu_measured_std is not None
    rounds = 1 if declared_noise else max(int(options.scatter_rounds), 1)
    # Progress: the first search takes most of it, each further one (run only when the scatter is not
    # one spread everywhere) half of what is left.
    edges = [0.0, *(1.0 - 0.3 * 0.5**k for k in range(rounds - 1)), 1.0]
    def search(weights, k):
        lo, hi = edges[min(k, rounds - 1)], edges[min(k + 1, rounds)]
        return _search(scatter_weighted(data, weights), data, fit_parameters, fold_rows, options,
                       declared_noise, lambda f: report(lo + (hi - lo) * f))

    given = None if rounds == 1 or _form(initial_scatter) == ("constant", None) else initial_scatter
    used: ScatterModel | None = given
    searches: list[tuple[ScatterModel | None, _SearchRun]] = []  # weights used and the search, per round
    fallback = ""
    for k in range(rounds):
        searches.append((used, search(used, k)))
        if rounds == 1:
            break
        estimate = selection_scatter(data, searches[-1][1].model, folds, seed)
        if _form(estimate) == _form(used):
            break  # consistent: the search's own residual has the scatter it was weighted by
        if used is not None and (_form(estimate) == ("constant", None) or k + 1 == rounds):
            # A weighted search whose residual no longer shows the scatter that weighted it (or rounds
            # that never settle): what looked like scatter was likely an effect the first search
            # missed, whose residual grows where it acts. The unweighted search stands.
            left = "is the same everywhere" if _form(estimate) == ("constant", None) else "differs"
            first = next(w for w, _ in searches if w is not None)
            origin = "given" if first is given else "of the unweighted search's residual"
            fallback = (f". A search weighted by the scatter {origin} ({first.summary()}) left a residual "
                        f"whose scatter {left} (it chose {_labels(searches[-1][1].model.terms)}): the "
                        f"scatter was not confirmed, and the unweighted search stands")
            unweighted = [item for item in searches if item[0] is None]
            searches = unweighted[:1] or [(None, search(None, rounds))]
            used = None
            break
        if k + 1 == rounds:
            break  # unweighted and the rounds are out: it stands
        if used is None and (absorbed := _scatter_of_an_effect(data, searches[-1][1], folds, seed)):
            # The spread read on the residual of a model that misses an effect grows where the effect
            # acts: the stopping step's best candidate, close to the threshold, takes it into the mean.
            fallback = (f". The held-out residual of the unweighted search's model scatters unevenly "
                        f"({estimate.summary()}), but that of its best candidate, {absorbed}, does not: "
                        f"the spread was that effect, not scatter, and the unweighted search stands")
            break
        used = estimate
    last = searches[-1][1]
    report(1.0)
    words = _selection_words(last, fallback, used, searches)
    return Selection(last.model.terms, last.steps, last.model, last.scale, rows, words, used)


def _scatter_of_an_effect(data: Dataset, run: _SearchRun, folds: int, seed: int) -> str | None:
    """The label of the stopping step's best close call (:func:`calibrate.scores.close_calls`) whose
    held-out residual scatters evenly, or None: the uneven spread of the model's residual was
    that candidate's effect, which a search weighted by it would hide (issue 33: a Kelvin law measured
    at 70-85 % RH read as scatter growing with the load, 6 % to 33 %, the weighted search then adding
    nothing and the model 50 % off where the runs were taken)."""
    close = close_calls(run.steps[-1]) if run.steps else []
    if not close:
        return None
    best = min(close, key=lambda c: c.score)
    spread = _held_out_scatter(data, best.oof_mu, folds, seed)
    return best.term.label if spread is not None and _form(spread) == ("constant", None) else None


def _selection_words(last: _SearchRun, fallback: str, used: ScatterModel | None,
                     searches: list[tuple[ScatterModel | None, _SearchRun]]) -> str:
    """The decision in words: each term added, why the search stopped, and the scatter that weighted it."""
    added = [s.reason for s in last.steps if s.chosen is not None]
    summary = "; then ".join(added) if added else "nothing added"
    words = f"{summary}. Stop: {last.reason}{fallback}"
    if used is not None:
        if len(searches) > 1:
            before = searches[-2][0]
            how = "unweighted" if before is None else f"weighted by {before.summary()}"
            source = (f"read from the held-out residual of the search before it (which chose "
                      f"{_labels(searches[-2][1].model.terms)}, {how})")
        else:
            source = "given (the scatter that weighted the search on all rows)"
        words += (f". The search weighted every row by its scatter, {used.summary()}, {source}; "
                  f"its own residual has a scatter of the same form")
    return words


def _labels(terms: Sequence[Term]) -> str:
    return " + ".join(t.label for t in terms) or "nothing"


@dataclass(frozen=True)
class _SearchRun:
    """One forward search: the final model cross-validated, its robust scale [1], the steps and why it
    stopped."""

    model: ModelCV
    scale: float
    steps: list[Step]
    reason: str


def _search(data, plain, fit_parameters, fold_rows, options: SearchOptions, declared_noise,
            report) -> _SearchRun:
    """One forward search on ``data`` (weighted or not; ``plain``: the same rows unweighted, for the
    words)."""
    convention = options.convention
    current = cross_validate(data, fit_parameters, (), fold_rows, precise=False, convention=convention)
    scale = current.full.scale
    steps: list[Step] = []
    reason = ""
    if np.unique(data.mu_measured).size == 1:
        return _SearchRun(current, scale, steps, "every row reads the same mu: constant data show no "
                          "dependence on anything measured, and no term is fitted")
    for k in range(options.max_terms):
        # Only declared noise is a level to test against: weights from the scatter model are fitted to
        # this very residual, and it would always look consistent with them.
        n_parameters = count_parameters(fit_parameters, current.terms)
        noise_p = noise_test(data, current.full.residual, n_parameters, scale) if declared_noise else None
        if noise_p is not None and noise_p > 0.01:
            reason = (
                f"the residual is consistent with mu_measured_std (chi-square p = {noise_p:.3g} > 0.01)"
                f": nothing more added"
            )
            break
        step = search_step(data, fit_parameters, current, scale, options,
                           lambda f, k=k: report((k + f) / options.max_terms), plain)
        steps.append(step)
        if step.chosen is None:
            reason = step.reason
            break
        # The scale is estimated afresh for the model with the new term, and the model is refitted
        # at it on every fold: the next step's candidates are fitted at that scale, and a current
        # model left at the previous, wider scale (where gross outliers pull almost as in least
        # squares) would make any refit at the new scale look like an improvement.
        current = cross_validate(
            data,
            fit_parameters,
            (*current.terms, step.chosen.term),
            fold_rows,
            start=shifted(current.full.declared, step.chosen.shifts),
            start_terms=[*current.full.term_values, step.chosen.values],
            precise=False,
            convention=convention,
        )
        scale = current.full.scale
    else:
        reason = f"stopped at {options.max_terms} terms (the most forward selection adds)"
    return _SearchRun(current, scale, steps, reason)


@dataclass(frozen=True)
class NestedValidation:
    """Outcome of :func:`nested_cross_validate`.

    Attributes
    ----------
    oof_mu : numpy.ndarray
        Held-out prediction of every row by the model that the whole procedure (declared fit,
        forward selection, fit of the chosen terms) built without the row's outer fold. [1]
    fold_terms : list of tuple of Term
        What the selection chose in each outer fold (empty: nothing added).
    unpredictable : int
        Outer folds whose chosen terms gave a non-finite or non-positive μ on their test rows
        (extrapolated beyond the training rows); those rows are predicted by the declared model
        fitted on the same training rows instead. [1]
    fold_mu : list of numpy.ndarray
        μ at every row of each outer fold's model (the one that predicted its test rows). [1]
    """

    oof_mu: np.ndarray = field(repr=False)
    fold_terms: list[tuple[Term, ...]]
    unpredictable: int
    fold_mu: list[np.ndarray] = field(default_factory=list, repr=False)

    def stability(self, chosen: Sequence[Term]) -> dict:
        """How often the outer folds agreed with ``chosen`` (the terms chosen on all rows).

        Parameters
        ----------
        chosen : sequence of Term
            The terms chosen on all rows (empty when nothing was added).

        Returns
        -------
        dict
            ``folds`` [1]; ``agreeing`` [1], outer folds that chose the same terms (in any order);
            ``same_driver`` [1], outer folds whose terms have the same main drivers, which counts a
            different form of the same dependence as agreeing; ``choices``, per outer fold
            ``{"effect", "drivers", "terms"}`` (``effect`` the first term's name or None, ``terms``
            every term's label); ``summary``, the same in words.

        Examples
        --------
        >>> from microbearing.calibrate.candidates import EffectTerm
        >>> pick = EffectTerm("run_in", ("cycle",))
        >>> v = NestedValidation(np.ones(3), [(pick,), (), (EffectTerm("run_in", ("cycle",)),)], 0)
        >>> v.stability([pick])["summary"]
        '2 of 3 outer folds chose run_in on cycle, as all rows did; 1 added nothing'
        >>> w = NestedValidation(np.ones(2), [(pick,), (EffectTerm("generic_power", ("cycle",)),)], 0)
        >>> s = w.stability([pick])
        >>> s["agreeing"], s["same_driver"]
        (1, 2)
        """

        def key(terms: Sequence[Term]) -> frozenset:
            return frozenset(t.label for t in terms)

        def drivers(terms: Sequence[Term]) -> frozenset:
            return frozenset(t.drivers[0] for t in terms)

        def words(terms: Sequence[Term]) -> str:
            return "added nothing" if not terms else "chose " + " + ".join(t.label for t in terms)

        target = key(chosen)
        agreeing = sum(key(t) == target for t in self.fold_terms)
        same_driver = sum(drivers(t) == drivers(chosen) for t in self.fold_terms)
        others: dict[frozenset, tuple[int, Sequence[Term]]] = {}
        for terms in self.fold_terms:
            if key(terms) != target:
                count, _ = others.get(key(terms), (0, terms))
                others[key(terms)] = (count + 1, terms)
        folds = len(self.fold_terms)
        summary = f"{agreeing} of {folds} outer folds {words(chosen)}, as all rows did"
        summary += "".join(
            f"; {count} {words(terms)}" for count, terms in sorted(others.values(), key=lambda item: -item[0])
        )
        if chosen and same_driver > agreeing:
            summary += f"; {same_driver} of {folds} on the driver(s) {', '.join(sorted(drivers(chosen)))}"
        if self.unpredictable:
            summary += (
                f"; in {self.unpredictable} fold(s) the chosen terms could not predict the "
                f"held-out rows, which the declared model predicted instead"
            )
        return {
            "folds": folds,
            "agreeing": agreeing,
            "same_driver": same_driver,
            "choices": [
                {
                    "effect": terms[0].name if terms else None,
                    "drivers": list(terms[0].drivers) if terms else [],
                    "terms": [t.label for t in terms],
                }
                for terms in self.fold_terms
            ],
            "summary": summary,
        }


def nested_cross_validate(
    dataset: Dataset,
    fit_parameters: Sequence[str],
    baseline: ModelCV,
    seed: int = 0,
    options: SearchOptions | None = None,
    progress: Callable[[float], None] | None = None,
    initial_scatter: ScatterModel | None = None,
) -> NestedValidation:
    """Cross-validate the whole procedure: forward selection repeated inside every training fold.

    For each outer fold of ``baseline`` (the declared model cross-validated on all rows), on the
    outer-training rows only: :func:`forward_select` with as many inner folds (same seed), then the
    chosen terms fitted jointly with the declared parameters on all those rows; the outer test rows
    are predicted by the result, or by the declared model fitted on the same rows when nothing was
    chosen. No row ever helps choose or fit the model that predicts it.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    fit_parameters : sequence of str
        Declared physics parameters fitted.
    baseline : ModelCV
        The declared model's fits on the outer folds.
    seed : int
        Seed of the inner folds' shuffle and search subsets.
    options : SearchOptions, optional
        As in :func:`forward_select`.
    progress : callable, optional
        Called with the fraction done, 0..1 (monotone).
    initial_scatter : ScatterModel, optional
        The scatter that weighted the search on all rows: each fold's search starts weighted by it
        and keeps it only when its own residual confirms it (see :func:`forward_select`).

    Returns
    -------
    NestedValidation
    """
    options = options or SearchOptions()
    report = progress or (lambda fraction: None)
    report(0.0)
    folds = len(baseline.folds)
    everything = np.arange(dataset.n_points)
    oof = np.empty(dataset.n_points)
    chosen: list[tuple[Term, ...]] = []
    models_mu: list[np.ndarray] = []
    unpredictable = 0
    for k, (test, fold_mu) in enumerate(zip(baseline.folds, baseline.fold_mu, strict=True)):
        train = np.setdiff1d(everything, test)
        inner = dataset.subset(train)
        selection = forward_select(inner, fit_parameters, folds, seed, options,
                                   lambda f, k=k: report((k + 0.95 * f) / folds), initial_scatter)
        oof[test] = fold_mu[test]
        chosen.append(selection.terms)
        model_mu = fold_mu
        if selection.terms:
            mu = _refit_chosen(dataset, inner, fit_parameters, selection, options.convention)
            if usable(mu):
                oof[test] = mu[test]
                model_mu = mu
            else:
                unpredictable += 1
        models_mu.append(model_mu)
        report((k + 1) / folds)
    return NestedValidation(oof, chosen, unpredictable, models_mu)


def held_out_of_chosen(nested: NestedValidation, dataset: Dataset, fit_parameters: Sequence[str],
                       final: FitResult, folds: list[np.ndarray], convention: str) -> np.ndarray:
    """Held-out μ of the terms chosen on all rows: ``nested.oof_mu``, except on the test rows of an outer
    fold whose selection chose other terms, which the chosen terms refitted on that fold's training rows
    predict instead.

    The scatter of a new measurement around the calibrated model is read on held-out residuals. A fold
    whose selection missed a term the data need (a term barely chosen on all rows, or whose driver's far
    end the fold held out whole, as a replicated design point) leaves residuals of *another model* there,
    often many times the noise; read as scatter, they would widen the chosen model's intervals where its
    data are best. Which terms to trust is the rivals' and the stability report's business, not the
    scatter's. Where every fold agreed, this is ``nested.oof_mu`` itself. A refit that cannot predict its
    test rows (a driver outside a term's domain) keeps the fold's own prediction.

    Parameters
    ----------
    nested : NestedValidation
        The whole procedure cross-validated on ``folds``.
    dataset : Dataset
        Measurements.
    fit_parameters : sequence of str
        Declared physics parameters fitted.
    final : FitResult
        The chosen terms' fit on all rows (its declared values and term values start every refit).
    folds : list of numpy.ndarray
        Test rows of each outer fold, in ``nested``'s order.
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    numpy.ndarray
        Held-out μ of every row. [1]
    """
    chosen = frozenset(t.label for t in final.terms)
    differing = [k for k, terms in enumerate(nested.fold_terms)
                 if frozenset(t.label for t in terms) != chosen]
    if not differing:
        return nested.oof_mu
    oof = nested.oof_mu.copy()
    everything = np.arange(dataset.n_points)
    for k in differing:
        test = folds[k]
        with np.errstate(all="ignore"):
            try:
                refit = fit(dataset, fit_parameters, final.terms, rows=np.setdiff1d(everything, test),
                            start=final.declared, start_terms=final.term_values, scale=final.scale,
                            convention=convention)
                mu = predict_mu(dataset, refit.declared, final.terms, refit.term_values,
                                convention=convention)[test]
            except ValueError:  # a held-out driver outside a term's domain
                continue
        if usable(mu):
            oof[test] = mu
    return oof


def _refit_chosen(dataset: Dataset, inner: Dataset, fit_parameters, selection: Selection,
                  convention: str) -> np.ndarray:
    """μ at every row of the chosen terms fitted jointly on a fold's training rows (NaN where a held-out
    driver lies outside a term's domain). [1]"""
    with np.errstate(all="ignore"):
        try:
            result = fit(
                scatter_weighted(inner, selection.scatter),
                fit_parameters,
                selection.terms,
                start=selection.model.full.declared,
                start_terms=selection.model.full.term_values,
                scale=selection.scale,
                convention=convention,
            )
            return predict_mu(
                dataset, result.declared, selection.terms, result.term_values, convention=convention
            )
        except ValueError:  # a held-out driver outside a term's domain
            return np.full(dataset.n_points, np.nan)


@dataclass(frozen=True)
class WithinGroups:
    """The chosen terms cross-validated with a level per group (:func:`held_out_within_groups`)."""

    cv: ModelCV
    held_out: np.ndarray


def held_out_within_groups(dataset: Dataset, fit_parameters: Sequence[str], final: FitResult,
                           folds: list[np.ndarray], convention: str) -> WithinGroups | None:
    """With groups the search fits levels for (:func:`with_search_groups`), the chosen terms refitted on each
    outer fold's training rows with a level per group, and the held-out log residual they leave: a held-out
    row loses its group's level estimated on that fold's training rows, where a fold's population fit
    keeps that fold's mix of groups in its residual (a GP and a scatter that varies would be judged on it).
    None without such groups or chosen terms."""
    grouped = with_search_groups(dataset)
    if grouped.search_groups is None or not final.terms:
        return None
    cv = cross_validate(grouped, fit_parameters, final.terms, folds, scale=final.scale, start=final.declared,
                        start_terms=final.term_values, precise=False, convention=convention)
    with np.errstate(all="ignore"):
        return WithinGroups(cv, np.log(dataset.mu_measured / cv.oof_mu))

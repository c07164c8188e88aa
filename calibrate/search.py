"""One step of forward selection (:mod:`calibrate.select`): every candidate screened on the current model
frozen at every row, the best refitted jointly on each fold, and the one named (or the reason none is).

See :mod:`calibrate.select` for the rule; :class:`SearchOptions` holds what a search may be told.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from microbearing import physics

from .candidates import FrozenBase, candidate_terms, mu_of, placed_on
from .credibility import implausible
from .data import Dataset
from .fit import fit, huber_loss, level_factor, predict_mu, weighted_log_residual
from .scores import (
    CandidateScore,
    ModelCV,
    Step,
    count_parameters,
    max_t_threshold,
    preferred,
    rms,
    score_of,
    usable,
    within_one_se,
)

__all__ = [
    "FAMILY_ALPHA",
    "MAX_SEARCH_ROWS",
    "MAX_TERMS",
    "SCATTER_ROUNDS",
    "SearchOptions",
    "bump_factor",
    "frozen_base",
    "search_step",
    "shifted",
]

#: Most terms forward selection adds. [1]
MAX_TERMS = 3
#: Chance, per step, that any candidate passes the paired test on noise alone. [1]
FAMILY_ALPHA = 0.01
#: The search runs on at most this many rows (a random subset); the chosen terms are then fitted
#: on all rows. A few thousand rows name an effect as surely as ten thousand, at a fraction of the cost. [1]
MAX_SEARCH_ROWS = 1000
#: Selections at most when the scatter model that weights the selection is re-estimated from the selected
#: model (see :func:`forward_select`): the first unweighted, each next one weighted by the scatter of the
#: one before, until the scatter model keeps its form. [1]
SCATTER_ROUNDS = 3
# Relative step of the sensitivities d log mu / d log p of the frozen base.
_SENSITIVITY_STEP = 1e-4
# A parameter whose largest sensitivity d log mu / d log p is below this cannot drift visibly: a 10 %
# change of it would move mu by less than 0.1 %. [1]
_INERT = 0.01


@dataclass(frozen=True)
class SearchOptions:
    """How forward selection searches (:func:`calibrate.select.forward_select`).

    Attributes
    ----------
    z_threshold : float
        Least paired z of a candidate's held-out improvement (raised by the family-wise correction, see
        :mod:`calibrate.select`). [1]
    joint_top : int
        How many of the best screened candidates, overall and among named ones, are refitted jointly. [1]
    max_terms : int
        Most terms added. [1]
    max_rows : int
        Rows the search runs on at most (:data:`MAX_SEARCH_ROWS`). [1]
    convention : str
        See :data:`physics.CONVENTIONS`.
    family_alpha : float or None
        Chance per step that any candidate passes on noise alone (:data:`FAMILY_ALPHA`); None leaves
        ``z_threshold`` alone. [1]
    scatter_rounds : int
        Searches at most (:data:`SCATTER_ROUNDS`); 1 leaves the search unweighted. [1]
    claim : bool
        Whether a step may add a term. False: a look on rows too few for nested cross-validation to weigh
        one (:func:`calibrate.decidability.terms_supported` is 0): every candidate is scored as in any
        step, on the single level of folds the rows allow, and none is added; the candidates the rows
        lean to are held as rivals (:func:`calibrate.rivals.undecided_candidates`).
    """

    z_threshold: float = 3.0
    joint_top: int = 2
    max_terms: int = MAX_TERMS
    max_rows: int = MAX_SEARCH_ROWS
    convention: str = physics.DEFAULT_CONVENTION
    family_alpha: float | None = FAMILY_ALPHA
    scatter_rounds: int = SCATTER_ROUNDS
    claim: bool = True


def frozen_base(dataset, fit_parameters, current: ModelCV, parameters, convention) -> FrozenBase:
    """The current model's full fit frozen at every row, with its sensitivity to each parameter."""
    full = current.full
    mu = predict_mu(dataset, full.declared, current.terms, full.term_values, convention=convention)
    inputs = {**physics.defaults(), **dataset.inputs(), **full.declared}
    sensitivity = {}
    for name in dict.fromkeys([*fit_parameters, *parameters]):
        value = np.asarray(inputs[name], dtype=float)
        factor = bump_factor(name, value)
        bumped = {**inputs, name: value * factor}
        with np.errstate(all="ignore"):
            mu_bumped = mu_of(
                bumped, dataset.conditions, current.terms, full.term_values, convention=convention
            )
            s = np.log(mu_bumped / mu) / np.log(factor)
        sensitivity[name] = np.where(np.isfinite(s), s, 0.0)
    # with groups (Dataset.search_groups) the frozen model carries each row's group level
    return FrozenBase(mu * level_factor(dataset, full), sensitivity, tuple(fit_parameters))


def bump_factor(name: str, value: np.ndarray) -> float:
    """Relative step of a sensitivity d log mu / d log p: up by :data:`_SENSITIVITY_STEP`, or down when a
    value on (or within a step of) the top of its range would leave it (a fitted parameter on its bound
    is an answer, not an error). [1]"""
    spec = physics.PARAMETERS[name]
    up = 1.0 + _SENSITIVITY_STEP
    if spec.maximum is None or value.size == 0:
        return up
    top = float(np.max(value)) * up
    inside = top < spec.maximum if spec.exclusive_maximum else top <= spec.maximum
    return up if inside else 1.0 - _SENSITIVITY_STEP


def _screen(dataset, fit_parameters, current: ModelCV, term, base, scale, current_loss):
    """In-sample score of a candidate fitted on the frozen base (declared parameters shifted to first
    order), or None when it cannot be evaluated at every row."""
    with np.errstate(all="ignore"):
        try:
            result = fit(dataset, (), (term,), base=base, scale=scale, precise=False)
            mu = predict_mu(
                dataset, {}, (term,), result.term_values, base=base.shifted(list(result.declared.values()))
            ) * level_factor(dataset, result)
        except ValueError:
            return None
    if not usable(mu):
        return None
    n_parameters = count_parameters(fit_parameters, (*current.terms, term))
    score = score_of(dataset, term, n_parameters, mu, current_loss, scale, False)
    return replace(score, values=list(result.term_values[0]), shifts=dict(result.declared))


def _screen_exactly(
    dataset, fit_parameters, current: ModelCV, screened: CandidateScore, scale, current_loss, convention
):
    """In-sample score of a candidate refitted with everything through the physics, or None."""
    terms = (*current.terms, screened.term)
    with np.errstate(all="ignore"):
        try:
            result = fit(
                dataset,
                fit_parameters,
                terms,
                start=shifted(current.full.declared, screened.shifts),
                start_terms=[*current.full.term_values, screened.values],
                scale=scale,
                precise=False,
                convention=convention,
            )
            mu = predict_mu(dataset, result.declared, terms, result.term_values,
                            convention=convention) * level_factor(dataset, result)
        except ValueError:
            return None
    if not usable(mu):
        return None
    score = score_of(dataset, screened.term, screened.n_parameters, mu, current_loss, scale, False)
    with np.errstate(divide="ignore", invalid="ignore"):
        shifts = {n: float(np.log(v / current.full.declared[n])) for n, v in result.declared.items()}
    return replace(score, values=list(result.term_values[-1]),
                   shifts={n: d if np.isfinite(d) else 0.0 for n, d in shifts.items()})


def shifted(declared: dict[str, float], shifts: dict[str, float]) -> dict[str, float]:
    """Declared values shifted by relative amounts (log scale)."""
    return {n: v * float(np.exp(shifts.get(n, 0.0))) for n, v in declared.items()}


def _cv_candidate(dataset, fit_parameters, current: ModelCV, screened: CandidateScore, scale, convention):
    """Held-out μ of every row with the candidate refitted jointly, or None when a fold cannot predict (a
    searched place is searched again on each fold's training rows)."""
    everything = np.arange(dataset.n_points)
    oof = np.empty(dataset.n_points)
    terms = (*current.terms, screened.term)
    columns = {**physics.defaults(), **dataset.inputs(), **dataset.conditions}
    for test, fold_fit in zip(current.folds, current.fold_fits, strict=True):
        train = np.setdiff1d(everything, test)
        with np.errstate(all="ignore"):
            try:
                if screened.term.searched:  # a step's place searched again on the fold's training rows
                    mu = predict_mu(dataset, fold_fit.declared, current.terms, fold_fit.term_values,
                                    convention=convention) * level_factor(dataset, fold_fit)
                    terms = (*current.terms, placed_on(screened.term, columns,
                                                       np.log(dataset.mu_measured / mu), train))
                result = fit(
                    dataset,
                    fit_parameters,
                    terms,
                    rows=train,
                    start=shifted(fold_fit.declared, screened.shifts),
                    start_terms=[*fold_fit.term_values, screened.values],
                    scale=scale,
                    precise=False,
                    convention=convention,
                )
                oof[test] = predict_mu(
                    dataset, result.declared, terms, result.term_values, rows=test, convention=convention
                ) * level_factor(dataset, result, test)
            except ValueError:  # a held-out driver value outside the term's domain
                return None
    # A term extrapolated to a held-out driver value can overflow: the candidate then fails.
    return oof if usable(oof) else None


def search_step(
    dataset: Dataset,
    fit_parameters: Sequence[str],
    current: ModelCV,
    scale: float,
    options: SearchOptions,
    progress: Callable[[float], None],
    plain: Dataset | None = None,
) -> Step:
    """One step of forward selection from ``current``: the candidates scored and the one added, if any.

    Parameters
    ----------
    dataset : Dataset
        The search rows (weighted by the scatter model or not).
    fit_parameters : sequence of str
        Declared physics parameters, refitted with every candidate.
    current : ModelCV
        The model before the step, cross-validated on the search's folds.
    scale : float
        Robust scale of the Huber loss (the current model's). [1]
    options : SearchOptions
        ``z_threshold``, ``family_alpha``, ``joint_top`` and ``convention`` act here.
    progress : callable
        Called with the fraction of the step done, 0..1.
    plain : Dataset, optional
        The same rows unweighted, for the errors in the words (default: ``dataset``).

    Returns
    -------
    Step
    """
    plain = dataset if plain is None else plain
    n_current = count_parameters(fit_parameters, current.terms)
    current_loss = huber_loss(weighted_log_residual(dataset, current.oof_mu), scale)
    current_score = score_of(dataset, None, n_current, current.oof_mu, current_loss, scale, True)
    screened, in_sample_loss = _screened(dataset, fit_parameters, current, scale, options, progress)
    z_needed = _z_needed(screened, in_sample_loss, options)
    shortlist = _shortlist(screened, z_needed, options.joint_top)
    joint = []
    for i, candidate in enumerate(shortlist):
        oof = _cv_candidate(dataset, fit_parameters, current, candidate, scale, options.convention)
        if oof is not None:
            joint.append(
                replace(
                    score_of(dataset, candidate.term, candidate.n_parameters, oof, current_loss, scale, True),
                    values=candidate.values,
                    shifts=candidate.shifts,
                )
            )
        progress(0.3 + 0.7 * (i + 1) / len(shortlist))
    joint.sort(key=lambda c: c.score)
    finalists = {id(c.term) for c in joint}
    ranked = joint + [c for c in screened if id(c.term) not in finalists]
    # A named law whose values are physically implausible (calibrate.credibility) is not chosen: it loses
    # to a plausible candidate or a generic term, and the words name it.
    columns = {**dataset.inputs(), **dataset.conditions}
    refused = {id(c.term): why for c in joint if (why := implausible(
        c.term, c.values, columns, shifted(current.full.declared, c.shifts), dataset.fixed))}
    significant = [c for c in joint if c.score < current_score.score and c.z > z_needed
                   and id(c.term) not in refused] if options.claim else []
    named = "".join(f"; {why[0]} (implausible, not chosen)" for c in joint[:3]
                    if (why := refused.get(id(c.term))))
    if not significant:
        best = joint[0] if joint else None
        detail = (
            ""
            if best is None
            else (
                f" (best candidate {best.term.label}: score {best.score - current_score.score:+.1f}, "
                f"must fall; z = {best.z:.2f}, must exceed {z_needed:.2f})"
            )
        ) + named
        reason = ("no candidate beats the current model by more than noise in cross-validation"
                  if options.claim else
                  "the rows are too few for nested cross-validation to weigh a term: the candidates were "
                  "scored on one level of folds and none is claimed")
        return Step(current_score, ranked, None, z_needed, reason + detail)
    chosen = preferred(dataset, significant)
    return Step(current_score, ranked, chosen, z_needed,
                _chosen_words(plain, current, current_score, chosen, significant, z_needed) + named)


def _screened(dataset, fit_parameters, current: ModelCV, scale, options: SearchOptions, progress):
    """Every candidate scored in sample on the frozen base, best first (the best drifts rescored through
    the physics), and the current model's in-sample loss per row."""
    candidates = candidate_terms(dataset, current.terms, fit_parameters)
    drifting = sorted({t.parameter for t in candidates if t.kind == "drift"})
    base = frozen_base(dataset, fit_parameters, current, drifting, options.convention)
    # A drift of a parameter the model's μ does not depend on (e.g. mu_ball without touching balls)
    # cannot be told from no drift: it is not a candidate.
    inert = {p for p in drifting if np.max(np.abs(base.sensitivity[p])) < _INERT}
    candidates = [t for t in candidates if t.kind != "drift" or t.parameter not in inert]
    in_sample_loss = huber_loss(weighted_log_residual(dataset, base.mu), scale)
    screened = []
    for i, term in enumerate(candidates):
        score = _screen(dataset, fit_parameters, current, term, base, scale, in_sample_loss)
        if score is not None:
            screened.append(score)
        progress(0.3 * (i + 1) / max(len(candidates), 1))
    screened.sort(key=lambda c: c.score)
    # A drift's first-order screening flatters one that needs a large change of a parameter the physics
    # responds to non-linearly (an elastic modulus): the best few are screened again through the physics.
    exact = {}
    for candidate in [c for c in screened if c.term.kind == "drift"][: 2 * options.joint_top]:
        rescored = _screen_exactly(
            dataset, fit_parameters, current, candidate, scale, in_sample_loss, options.convention
        )
        if rescored is not None:
            exact[id(candidate)] = rescored
    ranked = sorted((exact.get(id(c), c) for c in screened), key=lambda c: c.score)
    return _best_places(ranked), in_sample_loss


def _best_places(screened: list[CandidateScore]) -> list[CandidateScore]:
    """The screened candidates with one place per term with a searched place (a step's): its best.

    The place is part of that candidate's fit, not a family of candidates: its joint refit searches it
    again on every fold's training rows (:func:`_cv_candidate`), so the held-out rows never chose it,
    and the score charges it as a fitted value. Left as one candidate per place, the family-wise
    threshold of every step on data with an order column rose by about 0.3 (3.1 -> 3.4 on 120 runs), and
    a linear drift of +8 % over 120 runs went unnamed in one of three data sets.
    """
    seen, out = set(), []
    for c in screened:
        key = (c.term.name, c.term.drivers) if c.term.searched else id(c)
        if key not in seen:
            seen.add(key)
            out.append(c)
    return out


def _z_needed(screened: list[CandidateScore], in_sample_loss: np.ndarray, options: SearchOptions) -> float:
    """The paired z a candidate of this step must exceed. [1]

    The family of a step is every candidate screened; their correlation is read from the screening's
    per-row gains (the candidates refitted jointly are a few of them, chosen by these gains).
    """
    if options.family_alpha is None or not screened:
        return options.z_threshold
    gains = np.stack([in_sample_loss - c.loss for c in screened], axis=1)
    return max(options.z_threshold, max_t_threshold(gains, options.family_alpha))


def _shortlist(screened: list[CandidateScore], z_needed: float, joint_top: int) -> list[CandidateScore]:
    """The screened candidates refitted jointly: the best overall, among catalogue effects and among
    drifts, and the named ones that screen as well as the best."""
    effects = [c for c in screened if c.term.kind == "effect" and not c.term.generic]
    drifts = [c for c in screened if c.term.kind == "drift"]
    # Named terms that screen as well as the best, within one standard error, are refitted jointly too,
    # so that the preference among equals can act on all of them: near-duplicates (the ball and
    # the race modulus, which enter the physics only through the effective modulus) would otherwise
    # fill the shortlist and leave out an equal that asks less of its parameter.
    # Only when the best passes the paired test in sample (with nothing that strong on screening, the
    # extra refits would be spent on a step that is not going to add anything).
    equals = [
        c
        for c in screened[1:]
        if screened[0].z > z_needed and not c.term.generic and within_one_se(c.loss, screened[0].loss)
    ][: 2 * joint_top]
    return list(
        {id(c): c for c in screened[:joint_top] + effects[:joint_top] + drifts[:joint_top] + equals}.values()
    )


def _chosen_words(plain: Dataset, current: ModelCV, current_score: CandidateScore, chosen: CandidateScore,
                  significant: list[CandidateScore], z_needed: float) -> str:
    """Why ``chosen`` was added, and which candidates did as well within one standard error."""
    kind = (
        "generic term (no named mechanism fits)"
        if chosen.term.generic
        else "parameter drift"
        if chosen.term.kind == "drift"
        else "named effect"
    )
    rival = [
        c.term.label
        for c in significant
        if c is not chosen and within_one_se(c.loss, chosen.loss)
    ]
    reason = (
        f"{kind} {chosen.term.label}: CV RMSE of log mu "
        f"{rms(plain, current.oof_mu):.4g} -> {rms(plain, chosen.oof_mu):.4g}, "
        f"score {chosen.score - current_score.score:+.1f}, z = {chosen.z:.1f} (> {z_needed:.2f})"
    )
    if rival:
        reason += f"; as good within one standard error: {', '.join(rival[:3])}"
    return reason

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

import numpy as np
from scipy import stats

from microbearing import physics

from .candidates import FrozenBase, Term, candidate_terms, mu_of
from .data import Dataset
from .fit import FitResult, fit, huber_loss, kfold_indices, predict_mu, weighted_log_residual
from .scatter import ScatterModel, fit_scatter

__all__ = [
    "FAMILY_ALPHA",
    "MAX_SEARCH_ROWS",
    "MAX_TERMS",
    "SCATTER_ROUNDS",
    "SIGN_FLIPS",
    "CandidateScore",
    "ModelCV",
    "NestedValidation",
    "Selection",
    "Step",
    "cross_validate",
    "forward_select",
    "max_t_threshold",
    "nested_cross_validate",
    "noise_test",
    "preferred",
    "scatter_weighted",
    "varying_columns",
]

#: Most terms forward selection adds. [1]
MAX_TERMS = 3
#: Chance, per step, that any candidate passes the paired test on noise alone. [1]
FAMILY_ALPHA = 0.01
#: Random sign flips that estimate the family-wise threshold (:func:`max_t_threshold`): at α = 0.01,
#: 100 of them lie beyond it, and its Monte Carlo standard error is about 0.03 in z. [1]
SIGN_FLIPS = 10_000
# Sign flips drawn at a time (bounds the memory: chunk x rows signs).
_FLIP_CHUNK = 1000
#: The search runs on at most this many rows (a random subset); the chosen terms are then fitted
#: on all rows. A few thousand rows name an effect as surely as ten thousand, at a fraction of the cost. [1]
MAX_SEARCH_ROWS = 1000
#: Selections at most when the scatter model that weights the selection is re-estimated from the selected
#: model (see :func:`forward_select`): the first unweighted, each next one weighted by the scatter of the
#: one before, until the scatter model keeps its form. [1]
SCATTER_ROUNDS = 3
#: Candidates per step whose scores the report keeps. [1]
REPORTED_CANDIDATES = 15
# Relative step of the sensitivities d log mu / d log p of the frozen base.
_SENSITIVITY_STEP = 1e-4
# A parameter whose largest sensitivity d log mu / d log p is below this cannot drift visibly: a 10 %
# change of it would move mu by less than 0.1 %. [1]
_INERT = 0.01


@dataclass(frozen=True)
class ModelCV:
    """A model (declared parameters + terms) fitted on each training fold and on all rows.

    Attributes
    ----------
    terms : tuple of Term
        The model's terms.
    folds : list of numpy.ndarray
        Test rows of each fold.
    fold_fits : list of FitResult
        Fits without each fold's test rows.
    fold_mu : list of numpy.ndarray
        μ of each fold's fit at every row. [1]
    oof_mu : numpy.ndarray
        Held-out prediction of every row (from the fold that left it out). [1]
    full : FitResult
        Fit on all rows.
    """

    terms: tuple[Term, ...]
    folds: list[np.ndarray]
    fold_fits: list[FitResult]
    fold_mu: list[np.ndarray] = field(repr=False)
    oof_mu: np.ndarray = field(repr=False)
    full: FitResult


@dataclass(frozen=True)
class CandidateScore:
    """Cross-validated score of one candidate term (or of the current model, ``term`` None).

    Attributes
    ----------
    term : Term or None
        The candidate.
    n_parameters : int
        Fitted parameters in all, declared and terms'. [1]
    loss : numpy.ndarray
        Huber loss of every row's held-out weighted log residual. [1]
    score : float
        ``n log(mean loss) + n_parameters log(n)``, lower is better. [1]
    z : float
        Paired z of the decrease in held-out loss against the current model. [1]
    joint : bool
        True when refitted jointly with the declared parameters and chosen terms.
    oof_mu : numpy.ndarray
        Held-out prediction of every row (in-sample for a screening score). [1]
    values : list of float
        The term's parameters fitted by the screening (where a joint refit starts).
    shifts : dict of str to float
        Relative shifts (log scale) of the declared parameters the screening fitted with the term;
        a joint refit starts from them, not from the declared values that were bent to mimic it.
    """

    term: Term | None
    n_parameters: int
    loss: np.ndarray = field(repr=False)
    score: float
    z: float
    joint: bool
    oof_mu: np.ndarray = field(repr=False)
    values: list[float] = field(default_factory=list)
    shifts: dict[str, float] = field(default_factory=dict)

    def summary(self, dataset: Dataset) -> dict:
        """JSON-ready: term, kind, drivers, parameters, CV RMSE of log μ, score and z."""
        rms = float(np.sqrt(np.mean(np.square(weighted_log_residual(dataset, self.oof_mu)))))
        return {
            "effect": None if self.term is None else self.term.name,
            "kind": None if self.term is None else self.term.kind,
            "label": "current model" if self.term is None else self.term.label,
            "drivers": [] if self.term is None else list(self.term.drivers),
            "n_parameters": self.n_parameters,
            "cv_rmse_log": rms,
            "cv_robust_loss": float(np.mean(self.loss)),
            "score": float(self.score),
            "z_vs_declared": float(self.z),
            "joint_refit": self.joint,
        }


@dataclass(frozen=True)
class Step:
    """One step of forward selection.

    Attributes
    ----------
    current : CandidateScore
        The model before the step.
    ranked : list of CandidateScore
        Candidates scored, best first (joint refits before screening scores).
    chosen : CandidateScore or None
        The term added, or None when the search stopped.
    z_needed : float
        Paired z a candidate had to exceed. [1]
    reason : str
        Why it was added or why the search stopped.
    """

    current: CandidateScore
    ranked: list[CandidateScore]
    chosen: CandidateScore | None
    z_needed: float
    reason: str


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


def cross_validate(
    dataset: Dataset,
    fit_parameters: Sequence[str],
    terms: Sequence[Term],
    folds: list[np.ndarray],
    scale: float | None = None,
    start: Mapping[str, float] | None = None,
    start_terms: Sequence[Sequence[float]] | None = None,
    precise: bool = True,
    convention: str = physics.DEFAULT_CONVENTION,
) -> ModelCV:
    """Fit a model on all rows and on each training fold.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    fit_parameters : sequence of str
        Declared physics parameters to fit.
    terms : sequence of Term
        The model's terms.
    folds : list of numpy.ndarray
        Test rows of each fold (:func:`calibrate.fit.kfold_indices`).
    scale : float, optional
        Robust scale for the Huber loss (default: estimated by the fit on all rows, then used by
        every fold).
    start : mapping of str to float, optional
        Declared values to start from (default: the physics defaults).
    start_terms : sequence of sequence of float, optional
        Values of the first terms to start from (the others start from their data-based guess).
    precise : bool
        Whether the fits are precise (see :func:`calibrate.fit.fit`) or only good enough to rank.
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    ModelCV
    """
    full = fit(
        dataset,
        fit_parameters,
        terms,
        start=start,
        start_terms=start_terms,
        scale=scale,
        precise=precise,
        convention=convention,
    )
    everything = np.arange(dataset.n_points)
    fold_fits, fold_mu = [], []
    oof = np.empty(dataset.n_points)
    for test in folds:
        train = np.setdiff1d(everything, test)
        fold_fit = fit(
            dataset,
            fit_parameters,
            terms,
            rows=train,
            start=full.declared,
            start_terms=full.term_values,
            scale=full.scale,
            precise=precise,
            convention=convention,
        )
        with np.errstate(all="ignore"):
            mu = predict_mu(dataset, fold_fit.declared, terms, fold_fit.term_values, convention=convention)
        fold_fits.append(fold_fit)
        fold_mu.append(mu)
        oof[test] = mu[test]
    return ModelCV(tuple(terms), folds, fold_fits, fold_mu, oof, full)


def noise_test(dataset: Dataset, residual: np.ndarray, n_parameters: int, scale: float) -> float | None:
    """Chi-square p-value of the weighted log residual against ``mu_measured_std`` (None without it).

    Rows beyond the outlier threshold of :func:`calibrate.uncertainty.outlier_threshold` are left
    out, so that a few gross outliers do not condemn a model that explains the rest within the noise.
    """
    if dataset.mu_measured_std is None:
        return None
    from .uncertainty import outlier_threshold

    inliers = np.abs(residual) <= outlier_threshold(residual.size) * scale
    chi2 = float(np.sum(np.square(residual[inliers])))
    return float(stats.chi2.sf(chi2, max(int(inliers.sum()) - n_parameters, 1)))


def max_t_threshold(differences: np.ndarray, alpha: float, flips: int = SIGN_FLIPS, seed: int = 0) -> float:
    """Paired z that the largest of several correlated paired z's exceeds with chance ``alpha`` on noise.

    Westfall and Young's single-step max-T [1]_ with random sign flips [2]_: every candidate's per-row
    differences are centred (no improvement on average: the null), then the same random signs flip
    row i of every candidate at once, which keeps the candidates' correlation (they are fitted to
    the same rows); the threshold is the ``1 - alpha`` quantile of the largest paired z over the
    candidates. With independent candidates it comes to the Šidák value Φ⁻¹((1 - α)^(1/m)), with
    identical ones to the single test's Φ⁻¹(1 - α). The flips condition on each row's size of
    difference, so a candidate whose gain sits on a few rows has, as its own z, a lighter tail.

    Parameters
    ----------
    differences : numpy.ndarray
        Per-row decrease of the loss, shape (rows, candidates). [1]
    alpha : float
        Chance that any candidate's z exceeds the threshold when none improves on average. [1]
    flips : int
        Random sign flips (:data:`SIGN_FLIPS`). [1]
    seed : int
        Seed of the flips (fixed: the same data give the same threshold).

    Returns
    -------
    float
        The threshold. [1]

    References
    ----------
    .. [1] P. H. Westfall and S. S. Young, *Resampling-Based Multiple Testing*, Wiley, 1993, ch. 2.
    .. [2] T. E. Nichols and A. P. Holmes, "Nonparametric permutation tests for functional
       neuroimaging", Human Brain Mapping 15 (2002) 1-25 (sign flips for one-sample tests, max-T).

    Examples
    --------
    Thirty copies of one candidate are one test (Φ⁻¹(0.99) = 2.33, within the Monte Carlo error):

    >>> one = np.random.default_rng(1).normal(size=(400, 1))
    >>> thirty = max_t_threshold(np.repeat(one, 30, axis=1), 0.01)
    >>> bool(np.isclose(thirty, max_t_threshold(one, 0.01))), round(thirty, 1)
    (True, 2.4)
    """
    d = np.asarray(differences, dtype=float)
    n = d.shape[0]
    centred = d - d.mean(axis=0)
    squares = np.sum(np.square(centred), axis=0)
    rng = np.random.default_rng(seed)
    largest = np.empty(flips)
    for start in range(0, flips, _FLIP_CHUNK):
        count = min(_FLIP_CHUNK, flips - start)
        # One random bit a row, 1 for the sign +1 and 0 for -1: as every centred column sums to zero,
        # sum(sign d) = 2 sum(bit d).
        bits = np.unpackbits(rng.integers(0, 256, (count, (n + 7) // 8), dtype=np.uint8), axis=1, count=n)
        mean = 2.0 * (bits.astype(float) @ centred) / n
        # Flipping signs keeps every row's square: only the mean moves in the paired variance.
        variance = np.maximum(squares - n * np.square(mean), 0.0) / (n - 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(variance > 0, mean / np.sqrt(variance / n), 0.0)
        largest[start : start + count] = z.max(axis=1)
    return float(np.quantile(largest, 1.0 - alpha))


def _usable(mu: np.ndarray) -> bool:
    """Whether every predicted μ is finite and positive (its log residual exists)."""
    return bool(np.all(np.isfinite(mu) & (mu > 0)))


def _n_parameters(fit_parameters: Sequence[str], terms: Sequence[Term]) -> int:
    return len(fit_parameters) + sum(len(t.parameter_names) for t in terms)


def _score(dataset, term, n_parameters, oof_mu, current_loss, scale, joint) -> CandidateScore:
    loss = huber_loss(weighted_log_residual(dataset, oof_mu), scale)
    n = dataset.n_points
    diff = current_loss - loss
    spread = float(np.std(diff, ddof=1)) if n > 1 else 0.0
    z = float(np.mean(diff) / (spread / np.sqrt(n))) if spread > 0 else 0.0
    score = n * np.log(max(float(np.mean(loss)), 1e-300)) + n_parameters * np.log(n)
    return CandidateScore(term, n_parameters, loss, float(score), z, joint, oof_mu)


def _frozen_base(dataset, fit_parameters, current: ModelCV, parameters, convention) -> FrozenBase:
    """The current model's full fit frozen at every row, with its sensitivity to each parameter."""
    full = current.full
    mu = predict_mu(dataset, full.declared, current.terms, full.term_values, convention=convention)
    inputs = {**physics.defaults(), **dataset.inputs(), **full.declared}
    sensitivity = {}
    for name in dict.fromkeys([*fit_parameters, *parameters]):
        value = np.asarray(inputs[name], dtype=float)
        factor = _bump_factor(name, value)
        bumped = {**inputs, name: value * factor}
        with np.errstate(all="ignore"):
            mu_bumped = mu_of(
                bumped, dataset.conditions, current.terms, full.term_values, convention=convention
            )
            s = np.log(mu_bumped / mu) / np.log(factor)
        sensitivity[name] = np.where(np.isfinite(s), s, 0.0)
    return FrozenBase(mu, sensitivity, tuple(fit_parameters))


def _bump_factor(name: str, value: np.ndarray) -> float:
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
            )
        except ValueError:
            return None
    if not _usable(mu):
        return None
    score = _score(
        dataset, term, _n_parameters(fit_parameters, (*current.terms, term)), mu, current_loss, scale, False
    )
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
                start=_shifted(current.full.declared, screened.shifts),
                start_terms=[*current.full.term_values, screened.values],
                scale=scale,
                precise=False,
                convention=convention,
            )
            mu = predict_mu(dataset, result.declared, terms, result.term_values, convention=convention)
        except ValueError:
            return None
    if not _usable(mu):
        return None
    score = _score(dataset, screened.term, screened.n_parameters, mu, current_loss, scale, False)
    with np.errstate(divide="ignore", invalid="ignore"):
        shifts = {n: float(np.log(v / current.full.declared[n])) for n, v in result.declared.items()}
    return replace(score, values=list(result.term_values[-1]),
                   shifts={n: d if np.isfinite(d) else 0.0 for n, d in shifts.items()})


def _shifted(declared: dict[str, float], shifts: dict[str, float]) -> dict[str, float]:
    """Declared values shifted by relative amounts (log scale)."""
    return {n: v * float(np.exp(shifts.get(n, 0.0))) for n, v in declared.items()}


def _cv_candidate(dataset, fit_parameters, current: ModelCV, screened: CandidateScore, scale, convention):
    """Held-out μ of every row with the candidate refitted jointly, or None when a fold cannot predict."""
    everything = np.arange(dataset.n_points)
    oof = np.empty(dataset.n_points)
    terms = (*current.terms, screened.term)
    for test, fold_fit in zip(current.folds, current.fold_fits, strict=True):
        train = np.setdiff1d(everything, test)
        with np.errstate(all="ignore"):
            try:
                result = fit(
                    dataset,
                    fit_parameters,
                    terms,
                    rows=train,
                    start=_shifted(fold_fit.declared, screened.shifts),
                    start_terms=[*fold_fit.term_values, screened.values],
                    scale=scale,
                    precise=False,
                    convention=convention,
                )
                oof[test] = predict_mu(
                    dataset, result.declared, terms, result.term_values, rows=test, convention=convention
                )
            except ValueError:  # a held-out driver value outside the term's domain
                return None
    # A term extrapolated to a held-out driver value can overflow: the candidate then fails.
    return oof if _usable(oof) else None


def _search_step(
    dataset,
    fit_parameters,
    current: ModelCV,
    scale,
    z_threshold,
    family_alpha,
    joint_top,
    convention,
    progress,
    plain=None,
) -> Step:
    plain = dataset if plain is None else plain
    n_current = _n_parameters(fit_parameters, current.terms)
    current_loss = huber_loss(weighted_log_residual(dataset, current.oof_mu), scale)
    current_score = _score(dataset, None, n_current, current.oof_mu, current_loss, scale, True)
    candidates = candidate_terms(dataset, current.terms, fit_parameters)
    drifting = sorted({t.parameter for t in candidates if t.kind == "drift"})
    base = _frozen_base(dataset, fit_parameters, current, drifting, convention)
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
    for candidate in [c for c in screened if c.term.kind == "drift"][: 2 * joint_top]:
        rescored = _screen_exactly(
            dataset, fit_parameters, current, candidate, scale, in_sample_loss, convention
        )
        if rescored is not None:
            exact[id(candidate)] = rescored
    screened = sorted((exact.get(id(c), c) for c in screened), key=lambda c: c.score)
    effects = [c for c in screened if c.term.kind == "effect" and not c.term.generic]
    drifts = [c for c in screened if c.term.kind == "drift"]
    # Named terms that screen as well as the best, within one standard error, are refitted jointly too,
    # so that the preference among equals below can act on all of them: near-duplicates (the ball and
    # the race modulus, which enter the physics only through the effective modulus) would otherwise
    # fill the shortlist and leave out an equal that asks less of its parameter.
    # Only when the best passes the paired test in sample (with nothing that strong on screening, the
    # extra refits would be spent on a step that is not going to add anything).
    # The family of a step is every candidate screened; their correlation is read from the screening's
    # per-row gains (the candidates refitted jointly below are a few of them, chosen by these gains).
    z_needed = (
        z_threshold
        if family_alpha is None or not screened
        else max(
            z_threshold,
            max_t_threshold(np.stack([in_sample_loss - c.loss for c in screened], axis=1), family_alpha),
        )
    )
    equals = [
        c
        for c in screened[1:]
        if screened[0].z > z_needed and not c.term.generic and _within_one_se(c.loss, screened[0].loss)
    ][: 2 * joint_top]
    shortlist = list(
        {id(c): c for c in screened[:joint_top] + effects[:joint_top] + drifts[:joint_top] + equals}.values()
    )
    joint = []
    for i, candidate in enumerate(shortlist):
        oof = _cv_candidate(dataset, fit_parameters, current, candidate, scale, convention)
        if oof is not None:
            joint.append(
                replace(
                    _score(dataset, candidate.term, candidate.n_parameters, oof, current_loss, scale, True),
                    values=candidate.values,
                    shifts=candidate.shifts,
                )
            )
        progress(0.3 + 0.7 * (i + 1) / len(shortlist))
    joint.sort(key=lambda c: c.score)
    finalists = {id(c.term) for c in joint}
    ranked = joint + [c for c in screened if id(c.term) not in finalists]
    significant = [c for c in joint if c.score < current_score.score and c.z > z_needed]
    if not significant:
        best = joint[0] if joint else None
        detail = (
            ""
            if best is None
            else (
                f" (best candidate {best.term.label}: score {best.score - current_score.score:+.1f}, "
                f"must fall; z = {best.z:.2f}, must exceed {z_needed:.2f})"
            )
        )
        return Step(
            current_score,
            ranked,
            None,
            z_needed,
            f"no candidate beats the current model by more than noise in cross-validation{detail}",
        )
    chosen = preferred(dataset, significant)
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
        if c is not chosen and _within_one_se(c.loss, chosen.loss)
    ]
    reason = (
        f"{kind} {chosen.term.label}: CV RMSE of log mu "
        f"{_rms(plain, current.oof_mu):.4g} -> {_rms(plain, chosen.oof_mu):.4g}, "
        f"score {chosen.score - current_score.score:+.1f}, z = {chosen.z:.1f} (> {z_needed:.2f})"
    )
    if rival:
        reason += f"; as good within one standard error: {', '.join(rival[:3])}"
    return Step(current_score, ranked, chosen, z_needed, reason)


def preferred(dataset: Dataset, candidates: Sequence[CandidateScore]) -> CandidateScore:
    """The candidate a step names among ``candidates`` (a non-empty list of jointly refitted scores).

    The rule (parsimony and the physics first): the lowest score wins, unless named terms (a catalogue
    effect or a drift of a declared parameter by its law) fit as well within one standard error of the
    paired per-row losses; then a named term is named, never the generic one: a catalogue effect
    first, then the drift that asks least of its parameter (the smallest change over the data), then
    the lowest score. So when two drivers move together and a generic term on one fits as well as a
    declared drift law on the other (a polynomial in the speed against the viscosity's Arrhenius law
    in the temperature that rises with it), the law is named; the report names the other too
    (:func:`calibrate.report.calibrate`'s confounding words, :mod:`calibrate.decidability`).
    """
    best = min(candidates, key=lambda c: c.score)
    close_named = [c for c in candidates if not c.term.generic and _within_one_se(c.loss, best.loss)]
    if not close_named:
        return best
    return min(close_named, key=lambda c: (c.term.kind == "drift", _drift_change(dataset, c), c.score))


def _within_one_se(loss: np.ndarray, reference: np.ndarray) -> bool:
    """Whether a mean per-row loss exceeds the reference's by at most one standard error of the paired
    difference."""
    difference = loss - reference
    return bool(np.mean(difference) <= np.std(difference, ddof=1) / np.sqrt(difference.size))


def _drift_change(dataset: Dataset, candidate: CandidateScore) -> float:
    """Largest |log(p(x) / p_ref)| of a drift over the data (its screening fit); 0 for other terms. [1]"""
    if candidate.term.kind != "drift":
        return 0.0
    with np.errstate(all="ignore"):
        factor = candidate.term.factor(dataset.conditions, candidate.values[0])
    return float(np.max(np.abs(np.log(np.clip(factor, 1e-300, None)))))


def _rms(dataset: Dataset, mu: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(weighted_log_residual(dataset, mu)))))


def search_rows(n_points: int, max_rows: int, seed: int) -> np.ndarray:
    """Rows the search runs on: all of them, or a sorted random subset of ``max_rows``."""
    if n_points <= max_rows:
        return np.arange(n_points)
    return np.sort(np.random.default_rng(seed).choice(n_points, max_rows, replace=False))


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
    if dataset.mu_measured_std is not None or not _usable(model.oof_mu):
        return None
    columns = varying_columns(dataset)
    if not columns:
        return None
    residual = np.log(dataset.mu_measured / model.oof_mu)
    return fit_scatter(columns, residual, min(folds, dataset.n_points), seed)


def _form(scatter: ScatterModel | None) -> tuple[str, str | None]:
    if scatter is None or scatter.kind == "constant":
        return ("constant", None)
    return (scatter.kind, scatter.column)


def forward_select(
    dataset: Dataset,
    fit_parameters: Sequence[str] = (),
    folds: int = 5,
    seed: int = 0,
    z_threshold: float = 3.0,
    joint_top: int = 2,
    max_terms: int = MAX_TERMS,
    max_rows: int = MAX_SEARCH_ROWS,
    progress: Callable[[float], None] | None = None,
    convention: str = physics.DEFAULT_CONVENTION,
    family_alpha: float | None = FAMILY_ALPHA,
    scatter_rounds: int = SCATTER_ROUNDS,
    initial_scatter: ScatterModel | None = None,
) -> Selection:
    """Add terms to the declared model one at a time while cross-validation shows more than noise.

    **Weighted by the scatter.** Where the scatter of the measurements depends on the inputs (stick-slip
    at low speed, a spread that grows with the load), an unweighted search lets the rows of large
    scatter speak as loudly as the quiet ones: their noise then passes for an effect, and a term that
    follows it can win. So the search is repeated, up to ``scatter_rounds`` times, weighted by the
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
    z_threshold : float
        Least paired z of a candidate's held-out improvement (raised by the family-wise
        correction, see the module's description). [1]
    family_alpha : float or None
        Chance per step that any candidate passes on noise alone (:data:`FAMILY_ALPHA`); None
        leaves ``z_threshold`` alone. [1]
    joint_top : int
        How many of the best screened candidates, overall and among named ones, are refitted
        jointly. [1]
    max_terms : int
        Most terms added. [1]
    max_rows : int
        Rows the search runs on at most (:data:`MAX_SEARCH_ROWS`). [1]
    progress : callable, optional
        Called with the fraction done, 0..1.
    convention : str
        See :data:`physics.CONVENTIONS`.
    scatter_rounds : int
        Searches at most (:data:`SCATTER_ROUNDS`); 1 leaves the search unweighted. [1]
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
    reached = [0.0]

    def report(fraction: float) -> None:  # monotone, whatever order the searches run in
        if fraction > reached[0] and progress is not None:
            reached[0] = fraction
            progress(fraction)

    rows = search_rows(dataset.n_points, max_rows, seed)
    data = dataset if rows.size == dataset.n_points else dataset.subset(rows)
    fold_rows = kfold_indices(data.n_points, folds, seed)
    declared_noise = data.mu_measured_std is not None
    rounds = 1 if declared_noise else max(int(scatter_rounds), 1)
    # Progress: the first search takes most of it, each further one (run only when the scatter is not
    # one spread everywhere) half of what is left.
    edges = [0.0, *(1.0 - 0.3 * 0.5**k for k in range(rounds - 1)), 1.0]
    def search(weights, k):
        lo, hi = edges[min(k, rounds - 1)], edges[min(k + 1, rounds)]
        return _search(scatter_weighted(data, weights), data, fit_parameters, fold_rows, z_threshold,
                       family_alpha, joint_top, max_terms, convention, declared_noise,
                       lambda f: report(lo + (hi - lo) * f))

    given = None if rounds == 1 or _form(initial_scatter) == ("constant", None) else initial_scatter
    used: ScatterModel | None = given
    searches = []  # (weights used, (model, scale, steps, reason)) of each round
    fallback = ""
    for k in range(rounds):
        searches.append((used, search(used, k)))
        if rounds == 1:
            break
        estimate = selection_scatter(data, searches[-1][1][0], folds, seed)
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
                        f"whose scatter {left} (it chose {_labels(searches[-1][1][0].terms)}): the scatter "
                        f"was not confirmed, and the unweighted search stands")
            unweighted = [item for item in searches if item[0] is None]
            searches = unweighted[:1] or [(None, search(None, rounds))]
            used = None
            break
        if k + 1 == rounds:
            break  # unweighted and the rounds are out: it stands
        used = estimate
    current, scale, steps, reason = searches[-1][1]
    report(1.0)
    added = [s.reason for s in steps if s.chosen is not None]
    summary = "; then ".join(added) if added else "nothing added"
    words = f"{summary}. Stop: {reason}{fallback}"
    if used is not None:
        if len(searches) > 1:
            before = searches[-2][0]
            how = "unweighted" if before is None else f"weighted by {before.summary()}"
            source = (f"read from the held-out residual of the search before it (which chose "
                      f"{_labels(searches[-2][1][0].terms)}, {how})")
        else:
            source = "given (the scatter that weighted the search on all rows)"
        words += (f". The search weighted every row by its scatter, {used.summary()}, {source}; "
                  f"its own residual has a scatter of the same form")
    return Selection(current.terms, steps, current, scale, rows, words, used)


def _labels(terms: Sequence[Term]) -> str:
    return " + ".join(t.label for t in terms) or "nothing"


def _search(data, plain, fit_parameters, fold_rows, z_threshold, family_alpha, joint_top, max_terms,
            convention, declared_noise, report):
    """One forward search on ``data`` (weighted or not; ``plain``: the same rows unweighted, for the
    words): the final model cross-validated, its scale, the steps and why it stopped."""
    current = cross_validate(data, fit_parameters, (), fold_rows, precise=False, convention=convention)
    scale = current.full.scale
    steps: list[Step] = []
    reason = ""
    for k in range(max_terms):
        # Only declared noise is a level to test against: weights from the scatter model are fitted to
        # this very residual, and it would always look consistent with them.
        n_parameters = _n_parameters(fit_parameters, current.terms)
        noise_p = noise_test(data, current.full.residual, n_parameters, scale) if declared_noise else None
        if noise_p is not None and noise_p > 0.01:
            reason = (
                f"the residual is consistent with mu_measured_std (chi-square p = {noise_p:.3g} > 0.01)"
                f": nothing more added"
            )
            break
        step = _search_step(
            data,
            fit_parameters,
            current,
            scale,
            z_threshold,
            family_alpha,
            joint_top,
            convention,
            lambda f, k=k: report((k + f) / max_terms),
            plain,
        )
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
            start=_shifted(current.full.declared, step.chosen.shifts),
            start_terms=[*current.full.term_values, step.chosen.values],
            precise=False,
            convention=convention,
        )
        scale = current.full.scale
    else:
        reason = f"stopped at {max_terms} terms (the most forward selection adds)"
    return current, scale, steps, reason


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
    z_threshold: float = 3.0,
    joint_top: int = 2,
    max_terms: int = MAX_TERMS,
    max_rows: int = MAX_SEARCH_ROWS,
    progress: Callable[[float], None] | None = None,
    convention: str = physics.DEFAULT_CONVENTION,
    family_alpha: float | None = FAMILY_ALPHA,
    scatter_rounds: int = SCATTER_ROUNDS,
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
    z_threshold, joint_top, max_terms, max_rows, family_alpha, scatter_rounds : float or int
        As in :func:`forward_select`.
    progress : callable, optional
        Called with the fraction done, 0..1 (monotone).
    convention : str
        See :data:`physics.CONVENTIONS`.
    initial_scatter : ScatterModel, optional
        The scatter that weighted the search on all rows: each fold's search starts weighted by it
        and keeps it only when its own residual confirms it (see :func:`forward_select`).

    Returns
    -------
    NestedValidation
    """
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
        selection = forward_select(
            inner,
            fit_parameters,
            folds,
            seed,
            z_threshold,
            joint_top,
            max_terms,
            max_rows,
            lambda f, k=k: report((k + 0.95 * f) / folds),
            convention,
            family_alpha,
            scatter_rounds,
            initial_scatter,
        )
        oof[test] = fold_mu[test]
        chosen.append(selection.terms)
        model_mu = fold_mu
        if selection.terms:
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
                    mu = predict_mu(
                        dataset, result.declared, selection.terms, result.term_values, convention=convention
                    )
                except ValueError:  # a held-out driver outside a term's domain
                    mu = np.full(dataset.n_points, np.nan)
            if _usable(mu):
                oof[test] = mu[test]
                model_mu = mu
            else:
                unpredictable += 1
        models_mu.append(model_mu)
        report((k + 1) / folds)
    return NestedValidation(oof, chosen, unpredictable, models_mu)

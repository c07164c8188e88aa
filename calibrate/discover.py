"""Decide whether the residual holds structure beyond noise, and name the effect that explains it.

Every effect of :data:`physics.effects.EFFECTS` is paired with every plausible
driver column of the data. Each pair is scored by k-fold cross-validation on
log μ with the same folds for all:

1. **Screening**: the effect's parameters are fitted alone on each training
   fold, on top of the declared model fitted to that fold.
2. **Joint refit**: the best screened candidates (overall and among the named
   effects) are refitted with the declared parameters jointly.

A candidate counts only if it beats the declared model on both

* a BIC-like score ``n log(CV MSE) + p log(n)`` (``p`` = all fitted parameters), and
* a paired test of the per-point held-out squared errors (``z > z_threshold``),

and, when ``mu_measured_std`` is given, only if the declared model's residual
is not already consistent with that noise (chi-square test at 1 %). Among the
candidates that count, the one with the lowest score wins, except that a named
physical effect whose CV error lies within one standard error of the winner's
is preferred to a generic term (the one-standard-error rule).

Choosing the best of a few dozen candidates on the same folds that score them
makes the winner's CV error optimistic (selection bias).
:func:`nested_cross_validate` therefore repeats the whole search inside each
training fold (outer folds, inner folds within their training rows) and
predicts each outer test fold with what that search chose: an honest held-out
error of the procedure, and how often it chose the same effect.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats

import physics
from physics.effects import EFFECTS

from .data import Dataset
from .fit import EffectChoice, FitResult, fit, kfold_indices, predict_mu

__all__ = ["Baseline", "CandidateScore", "Discovery", "NestedValidation", "cross_validate_baseline",
           "candidate_choices", "discover", "nested_cross_validate"]


@dataclass(frozen=True)
class Baseline:
    """The declared model fitted on each training fold and on all data.

    Attributes
    ----------
    folds : list of numpy.ndarray
        Test rows of each fold.
    fold_fits : list of FitResult
        Declared parameters fitted without each fold's test rows.
    fold_mu : list of numpy.ndarray
        μ of each fold's fitted declared model at every row. [1]
    oof_mu : numpy.ndarray
        Held-out prediction of every row (from the fold that left it out). [1]
    full_fit : FitResult
        Declared parameters fitted on all rows (the "before" model).
    """

    folds: list[np.ndarray]
    fold_fits: list[FitResult]
    fold_mu: list[np.ndarray] = field(repr=False)
    oof_mu: np.ndarray = field(repr=False)
    full_fit: FitResult


@dataclass(frozen=True)
class CandidateScore:
    """Cross-validated score of one effect and driver choice.

    Attributes
    ----------
    choice : EffectChoice or None
        None for the declared model alone.
    n_parameters : int
        Fitted parameters, declared and effect's. [1]
    cv_mse : float
        Mean squared held-out (weighted) log residual. [1]
    score : float
        ``n log(cv_mse) + n_parameters log(n)``, lower is better. [1]
    z_vs_baseline : float
        Paired z of the decrease in held-out squared error against the declared model. [1]
    joint : bool
        True when refitted jointly with the declared parameters, False for a screening score.
    oof_mu : numpy.ndarray
        Held-out prediction of every row. [1]
    """

    choice: EffectChoice | None
    n_parameters: int
    cv_mse: float
    score: float
    z_vs_baseline: float
    joint: bool
    oof_mu: np.ndarray = field(repr=False)

    def summary(self) -> dict:
        """JSON-ready summary: effect, drivers, parameter count, CV RMSE of log μ, score and z."""
        return {
            "effect": None if self.choice is None else self.choice.name,
            "drivers": [] if self.choice is None else list(self.choice.drivers),
            "n_parameters": self.n_parameters,
            "cv_rmse_log": float(np.sqrt(self.cv_mse)),
            "score": float(self.score),
            "z_vs_declared": float(self.z_vs_baseline),
            "joint_refit": self.joint,
        }


@dataclass(frozen=True)
class Discovery:
    """Outcome of :func:`discover`.

    Attributes
    ----------
    baseline : Baseline
        The declared model's fits.
    baseline_score : CandidateScore
        Its cross-validated score.
    candidates : list of CandidateScore
        Every candidate scored, best score first (joint refits before screening scores).
    chosen : CandidateScore or None
        The missing effect, or None when nothing beyond noise remains.
    reason : str
        Why it was chosen or why nothing was added.
    noise_p_value : float or None
        Chi-square p-value of the declared model's residual against ``mu_measured_std``.
    """

    baseline: Baseline
    baseline_score: CandidateScore
    candidates: list[CandidateScore]
    chosen: CandidateScore | None
    reason: str
    noise_p_value: float | None


def _weighted_log_residual(dataset: Dataset, mu: np.ndarray) -> np.ndarray:
    r = np.log(np.maximum(mu, 1e-300)) - np.log(dataset.mu_measured)
    return r if dataset.mu_measured_std is None else r * dataset.mu_measured / dataset.mu_measured_std


def cross_validate_baseline(dataset: Dataset, fit_parameters: Sequence[str], folds: int = 5, seed: int = 0,
                            convention: str = physics.DEFAULT_CONVENTION) -> Baseline:
    """Fit the declared model on all rows and on each training fold.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    fit_parameters : sequence of str
        Declared physics parameters to fit.
    folds : int
        Number of folds. [1]
    seed : int
        Seed of the fold shuffle.
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    Baseline
    """
    full = fit(dataset, fit_parameters, convention=convention)
    test_sets = kfold_indices(dataset.n_points, folds, seed)
    everything = np.arange(dataset.n_points)
    fold_fits, fold_mu = [], []
    oof = np.empty(dataset.n_points)
    for test in test_sets:
        train = np.setdiff1d(everything, test)
        fold_fit = fit(dataset, fit_parameters, rows=train, start=full.declared, convention=convention)
        mu = predict_mu(dataset, fold_fit.declared, convention=convention)
        fold_fits.append(fold_fit)
        fold_mu.append(mu)
        oof[test] = mu[test]
    return Baseline(test_sets, fold_fits, fold_mu, oof, full)


def candidate_choices(dataset: Dataset) -> list[EffectChoice]:
    """Every effect paired with every plausible driver of the data.

    Parameters
    ----------
    dataset : Dataset
        Measurements; a main driver must be a numeric data column taking at least the effect's
        ``min_levels`` distinct values (2 for a step on a two-level column such as 0/1, 3 for
        curved forms) and lie in the effect's domain.

    Returns
    -------
    list of EffectChoice
        Named effects first, then the generic family.
    """
    columns = {**physics.defaults(), **dataset.inputs(), **dataset.conditions}
    levels = {n: np.unique(v).size for n, v in dataset.columns().items() if v.dtype != bool}
    varying = [n for n, count in levels.items() if count >= 2]
    names = varying + [n for n in columns if n not in varying]
    choices = []
    for effect in EFFECTS.values():
        for drivers in effect.candidate_drivers(names):
            if levels.get(drivers[0], 0) >= effect.min_levels and effect.accepts(columns, drivers):
                choices.append(EffectChoice(effect.name, drivers, effect.constants(columns, drivers)))
    return choices


def _score(dataset, choice, n_parameters, oof_mu, baseline_sq, joint) -> CandidateScore:
    r = _weighted_log_residual(dataset, oof_mu)
    sq = r * r
    n = dataset.n_points
    mse = float(np.mean(sq))
    diff = baseline_sq - sq
    spread = float(np.std(diff, ddof=1)) if n > 1 else 0.0
    z = float(np.mean(diff) / (spread / np.sqrt(n))) if spread > 0 else 0.0
    score = n * np.log(max(mse, 1e-300)) + n_parameters * np.log(n)
    return CandidateScore(choice, n_parameters, mse, float(score), z, joint, oof_mu)


def _cv_candidate(dataset, baseline, fit_parameters, choice, joint, convention) -> np.ndarray | None:
    """Held-out μ of every row, or None when a fold's fit predicts a non-finite or non-positive μ."""
    everything = np.arange(dataset.n_points)
    oof = np.empty(dataset.n_points)
    for test, fold_fit, fold_mu in zip(baseline.folds, baseline.fold_fits, baseline.fold_mu, strict=True):
        train = np.setdiff1d(everything, test)
        with np.errstate(all="ignore"):
            if joint:
                result = fit(dataset, fit_parameters, choice, rows=train, start=fold_fit.declared,
                             convention=convention)
                oof[test] = predict_mu(dataset, result.declared, choice, result.effect_parameters, rows=test,
                                       convention=convention)
            else:
                result = fit(dataset, (), choice, rows=train, base_mu=fold_mu, convention=convention)
                oof[test] = predict_mu(dataset, {}, choice, result.effect_parameters, rows=test,
                                       base_mu=fold_mu, convention=convention)
    # A term extrapolated to a held-out driver value can overflow: the candidate then fails.
    return oof if _usable(oof) else None


def _usable(mu: np.ndarray) -> bool:
    """Whether every predicted μ is finite and positive (its log residual exists)."""
    return bool(np.all(np.isfinite(mu) & (mu > 0)))


def _paired_se(dataset, a: CandidateScore, b: CandidateScore) -> float:
    ra = _weighted_log_residual(dataset, a.oof_mu)
    rb = _weighted_log_residual(dataset, b.oof_mu)
    return float(np.std(ra * ra - rb * rb, ddof=1) / np.sqrt(dataset.n_points))


def discover(dataset: Dataset, fit_parameters: Sequence[str] = (), folds: int = 5, seed: int = 0,
             z_threshold: float = 3.0, joint_top: int = 3, baseline: Baseline | None = None,
             progress: Callable[[float], None] | None = None,
             convention: str = physics.DEFAULT_CONVENTION) -> Discovery:
    """Find the effect missing from the declared model, or decide that none is.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    fit_parameters : sequence of str
        Declared physics parameters fitted with every candidate.
    folds : int
        Number of cross-validation folds. [1]
    seed : int
        Seed of the fold shuffle.
    z_threshold : float
        Minimum paired z of the held-out improvement over the declared model; 3 keeps the
        false-alarm rate low across the few dozen candidates tried. [1]
    joint_top : int
        How many of the best screened candidates, overall and among named effects, are refitted
        jointly with the declared parameters. [1]
    baseline : Baseline, optional
        Result of :func:`cross_validate_baseline` with the same folds, when already computed.
    progress : callable, optional
        Called with the fraction done, 0..1.
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    Discovery

    Raises
    ------
    ValueError
        For invalid ``fit_parameters`` or ``folds``.
    """
    report = progress or (lambda fraction: None)
    if baseline is None:
        baseline = cross_validate_baseline(dataset, fit_parameters, folds, seed, convention)
    report(0.2)
    n_declared = len(baseline.full_fit.declared)
    base_r = _weighted_log_residual(dataset, baseline.oof_mu)
    base_sq = base_r * base_r
    base_score = _score(dataset, None, n_declared, baseline.oof_mu, base_sq, True)

    choices = candidate_choices(dataset)
    screened = []
    for i, choice in enumerate(choices):
        oof = _cv_candidate(dataset, baseline, fit_parameters, choice, False, convention)
        if oof is not None:
            screened.append(_score(dataset, choice, n_declared + len(choice.effect.parameters), oof, base_sq,
                                   False))
        report(0.2 + 0.4 * (i + 1) / max(len(choices), 1))
    screened.sort(key=lambda c: c.score)
    named = [c for c in screened if not c.choice.effect.generic]
    shortlist = list({id(c): c for c in screened[:joint_top] + named[:joint_top]}.values())
    joint = []
    if n_declared:
        for i, candidate in enumerate(shortlist):
            oof = _cv_candidate(dataset, baseline, fit_parameters, candidate.choice, True, convention)
            if oof is not None:
                joint.append(_score(dataset, candidate.choice, candidate.n_parameters, oof, base_sq, True))
            report(0.6 + 0.4 * (i + 1) / len(shortlist))
    else:
        # Nothing declared to refit: the screening fit is already the joint fit.
        joint = [replace(c, joint=True) for c in shortlist]
    joint.sort(key=lambda c: c.score)
    finalists = {id(c.choice) for c in joint}
    ranked = joint + [c for c in screened if id(c.choice) not in finalists]
    report(1.0)

    noise_p = None
    if dataset.mu_measured_std is not None:
        chi2 = float(np.sum(np.square(_weighted_log_residual(dataset, predict_mu(
            dataset, baseline.full_fit.declared, convention=convention)))))
        noise_p = float(stats.chi2.sf(chi2, max(dataset.n_points - n_declared, 1)))
        if noise_p > 0.01:
            reason = (f"the declared model's residual is consistent with mu_measured_std "
                      f"(chi-square p = {noise_p:.3g} > 0.01): nothing added")
            return Discovery(baseline, base_score, ranked, None, reason, noise_p)

    significant = [c for c in joint if c.score < base_score.score and c.z_vs_baseline > z_threshold]
    if not significant:
        best = joint[0] if joint else None
        detail = "" if best is None else (
            f" (best candidate {best.choice.name} on {best.choice.drivers[0]}: score "
            f"{best.score - base_score.score:+.1f}, z = {best.z_vs_baseline:.2f})")
        reason = ("no candidate beats the declared model by more than noise in cross-validation"
                  + detail + ": nothing added")
        return Discovery(baseline, base_score, ranked, None, reason, noise_p)
    best = min(significant, key=lambda c: c.score)
    close_named = [c for c in significant if not c.choice.effect.generic
                   and c.cv_mse - best.cv_mse <= _paired_se(dataset, c, best)]
    chosen = min(close_named, key=lambda c: c.score) if close_named else best
    kind = "named effect" if not chosen.choice.effect.generic else "generic term (no named effect fits)"
    reason = (f"{kind} {chosen.choice.name} on {', '.join(chosen.choice.drivers)}: CV RMSE of log mu "
              f"{np.sqrt(base_score.cv_mse):.4g} -> {np.sqrt(chosen.cv_mse):.4g}, "
              f"score {chosen.score - base_score.score:+.1f}, z = {chosen.z_vs_baseline:.1f}")
    return Discovery(baseline, base_score, ranked, chosen, reason, noise_p)



@dataclass(frozen=True)
class NestedValidation:
    """Outcome of :func:`nested_cross_validate`.

    Attributes
    ----------
    oof_mu : numpy.ndarray
        Held-out prediction of every row by the model that the whole procedure (declared fit,
        search, fit of the chosen effect) built without the row's outer fold. [1]
    fold_choices : list of EffectChoice or None
        What the search chose in each outer fold (None: nothing added).
    unpredictable : int
        Outer folds whose chosen effect gave a non-finite or non-positive μ on their test rows
        (extrapolated beyond the training rows); those rows are predicted by the declared model
        fitted on the same training rows instead. [1]
    """

    oof_mu: np.ndarray = field(repr=False)
    fold_choices: list[EffectChoice | None]
    unpredictable: int

    def stability(self, chosen: EffectChoice | None) -> dict:
        """How often the outer folds agreed with ``chosen`` (the choice made on all rows).

        Parameters
        ----------
        chosen : EffectChoice or None
            The effect the search chose on all rows, or None when it added nothing.

        Returns
        -------
        dict
            ``folds`` [1]; ``agreeing`` [1], outer folds that chose the same effect on the same
            drivers (or nothing, like the full data); ``same_driver`` [1], outer folds whose choice
            has the same main driver (or that added nothing, like the full data), which counts a
            different form of the same dependence as agreeing; ``choices``, per outer fold
            ``{"effect", "drivers"}`` (``effect`` None for nothing added); ``summary``, the same in
            words.

        Examples
        --------
        >>> pick = EffectChoice("run_in", ("cycle",))
        >>> v = NestedValidation(np.ones(3), [pick, None, EffectChoice("run_in", ("cycle",))], 0)
        >>> v.stability(pick)["summary"]
        '2 of 3 outer folds chose run_in on cycle, as all rows did; 1 added nothing'
        >>> w = NestedValidation(np.ones(2), [pick, EffectChoice("generic_power", ("cycle",))], 0)
        >>> s = w.stability(pick)
        >>> s["agreeing"], s["same_driver"]
        (1, 2)
        >>> print(s["summary"].replace("; ", "\\n"))
        1 of 2 outer folds chose run_in on cycle, as all rows did
        1 chose generic_power on cycle
        2 of 2 on the driver cycle
        """
        def key(choice: EffectChoice | None) -> tuple:
            return () if choice is None else (choice.name, tuple(choice.drivers))

        def words(k: tuple) -> str:
            return "added nothing" if not k else f"chose {k[0]} on {', '.join(k[1])}"

        keys = [key(c) for c in self.fold_choices]
        target = key(chosen)
        agreeing = sum(k == target for k in keys)
        same_driver = sum(k[1][:1] == target[1][:1] if k and target else k == target for k in keys)
        others: dict[tuple, int] = {}
        for k in keys:
            if k != target:
                others[k] = others.get(k, 0) + 1
        summary = f"{agreeing} of {len(keys)} outer folds {words(target)}, as all rows did"
        summary += "".join(f"; {count} {words(k)}" for k, count in
                           sorted(others.items(), key=lambda item: -item[1]))
        if target and same_driver > agreeing:
            summary += f"; {same_driver} of {len(keys)} on the driver {target[1][0]}"
        if self.unpredictable:
            summary += (f"; in {self.unpredictable} fold(s) the chosen effect could not predict the "
                        f"held-out rows, which the declared model predicted instead")
        return {
            "folds": len(keys),
            "agreeing": agreeing,
            "same_driver": same_driver,
            "choices": [{"effect": k[0] if k else None, "drivers": list(k[1]) if k else []} for k in keys],
            "summary": summary,
        }


def nested_cross_validate(dataset: Dataset, fit_parameters: Sequence[str], baseline: Baseline, seed: int = 0,
                          z_threshold: float = 3.0, joint_top: int = 3,
                          progress: Callable[[float], None] | None = None,
                          convention: str = physics.DEFAULT_CONVENTION) -> NestedValidation:
    """Cross-validate the whole search: discovery repeated inside every training fold.

    For each outer fold of ``baseline`` (the folds of :func:`cross_validate_baseline`), on the
    outer-training rows only: :func:`discover` with as many inner folds (same seed), then the
    chosen effect fitted jointly with the declared parameters (started from the declared fit of
    that fold); the outer test rows are predicted by the result, or by the declared model fitted
    on the same rows (``baseline.fold_mu``) when nothing was chosen. No row ever helps choose or
    fit the model that predicts it, so the error of :attr:`NestedValidation.oof_mu` is free of
    the selection bias of the winning candidate's own CV error.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    fit_parameters : sequence of str
        Declared physics parameters fitted.
    baseline : Baseline
        The declared model's fits on the outer folds.
    seed : int
        Seed of the inner folds' shuffle (the outer folds are ``baseline.folds``).
    z_threshold, joint_top : float, int
        As in :func:`discover`.
    progress : callable, optional
        Called with the fraction done, 0..1 (monotone).
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    NestedValidation
    """
    report = progress or (lambda fraction: None)
    report(0.0)
    folds = len(baseline.folds)
    everything = np.arange(dataset.n_points)
    oof = np.empty(dataset.n_points)
    choices: list[EffectChoice | None] = []
    unpredictable = 0
    for k, (test, fold_fit, fold_mu) in enumerate(zip(baseline.folds, baseline.fold_fits, baseline.fold_mu,
                                                      strict=True)):
        train = np.setdiff1d(everything, test)
        inner = dataset.subset(train)
        found = discover(inner, fit_parameters, folds, seed, z_threshold, joint_top,
                         progress=lambda f, k=k: report((k + 0.95 * f) / folds), convention=convention)
        oof[test] = fold_mu[test]
        if found.chosen is None:
            choices.append(None)
        else:
            choice = found.chosen.choice
            choices.append(choice)
            with np.errstate(all="ignore"):
                result = fit(inner, fit_parameters, choice, start=fold_fit.declared, convention=convention)
                mu = predict_mu(dataset, result.declared, choice, result.effect_parameters, rows=test,
                                convention=convention)
            if _usable(mu):
                oof[test] = mu
            else:
                unpredictable += 1
        report((k + 1) / folds)
    return NestedValidation(oof, choices, unpredictable)

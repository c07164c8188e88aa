"""Say when the data cannot decide, and roughly where more rows would settle it.

A selection step adds a term when its held-out paired z exceeds the step's threshold
(:mod:`calibrate.select`); on data with nothing to find the best candidate's z stays below about 2.2
in 99 % of data sets of 200 rows (bench/RESULTS.md, ``--part null``). A candidate whose z falls just
short of the threshold, or a term that passed just above it, is therefore a question the data
leave open, not a verdict. :func:`undecided` lists, for the report and for planning the next
experiments:

* ``near_threshold``: the best candidate of the step that stopped, when its z lies within
  :data:`CLOSE_MARGIN` below the threshold, or above :data:`CLOSE_Z` while it lowers the selection's
  score (on few rows the threshold is out of a real effect's reach). "Best" is by the selection's own
  rule (:func:`calibrate.select.preferred`: a named law before a generic term that fits as well), and
  every close candidate that fits as well within one standard error is named with it, with the
  drivers the data cannot tell apart;
* ``barely_chosen``: a term added with z within :data:`CLOSE_MARGIN` above the threshold, or chosen by
  fewer than half of the outer folds of the nested cross-validation;
* ``rivals``: terms that fit about as well as a chosen one and part ways somewhere
  (:mod:`calibrate.rivals`).

Each item says where new rows would tell the answers apart: the range of the term's main driver over
the quarter of the rows where the candidate and the model without it differ most (held out), and,
for rivals, the driver values where they differ by more than a measurement's scatter. The paired z
of an effect that is there grows as √n, so about ``n (z_needed / z)²`` rows drawn like these would
carry it over the threshold (:func:`rows_to_settle`); fewer if they are placed where it acts.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from microbearing import physics as _physics

from .candidates import Term, mu_of
from .data import Dataset
from .fit import fit
from .prose import in_sent_units, located
from .rivals import where_they_part
from .scores import CLOSE_MARGIN, CLOSE_Z, close_calls, within_one_se
from .select import CandidateScore, Selection, preferred, search_data

__all__ = ["CLOSE_MARGIN", "CLOSE_Z", "few_rows", "rows_for_gp", "rows_for_terms", "rows_to_settle",
           "terms_supported", "undecided"]

# Where a term acts most: its effect there is at least this share of its largest. [1]
_HALF = 0.5
# Share of the rows, those where the two models differ most, whose driver range says where they differ.
_TOP_SHARE = 0.25


def rows_to_settle(n_rows: int, z: float, z_needed: float) -> int | None:
    """Rows drawn like the present ones that would carry a paired z of ``z`` on ``n_rows`` rows to
    ``z_needed`` (z grows as √n): ``ceil(n_rows (z_needed / z)²)``; None for z <= 0.

    Examples
    --------
    >>> rows_to_settle(24, 2.4, 3.4)
    49
    """
    if z <= 0:
        return None
    return int(np.ceil(n_rows * (z_needed / z) ** 2))


def rows_for_terms(n_fit_parameters: int, folds: int, terms: int) -> int:
    """Fewest rows for nested cross-validation of a model with ``terms`` two-parameter terms: every inner
    training set two rows more than its fitted values, every inner test fold at least one row. [1]

    Examples
    --------
    >>> rows_for_terms(1, 5, 0), rows_for_terms(1, 5, 1), rows_for_terms(2, 5, 3)
    (7, 8, 16)
    """
    keep = (1.0 - 1.0 / folds) ** 2
    return max(int(np.ceil((n_fit_parameters + 2 * terms + 2) / keep)),
               int(np.ceil(folds / (1.0 - 1.0 / folds))))


def rows_for_gp(n_fit_parameters: int, folds: int, features: int) -> int:
    """Fewest rows on which a GP discrepancy over ``features`` columns may join the model: its
    hyperparameters (an amplitude, a length scale per column, the white noise) count as fitted values, in
    pairs like a term's (:func:`rows_for_terms`). On fewer rows the marginal likelihood can put the white
    noise at its bound and the GP through every row: an interval with no scatter in it. [1]

    Examples
    --------
    >>> rows_for_gp(1, 4, 5), rows_for_gp(1, 5, 5), rows_for_gp(2, 5, 8)
    (20, 18, 22)
    """
    return rows_for_terms(n_fit_parameters, folds, -(-(features + 2) // 2))


def terms_supported(n_rows: int, n_fit_parameters: int, folds: int, most: int) -> int:
    """Most two-parameter terms (at most ``most``) whose model nested cross-validation can fit and judge on
    ``n_rows`` rows (:func:`rows_for_terms`); 0 when only the declared model can. [1]

    Examples
    --------
    >>> terms_supported(8, 1, 4, 3), terms_supported(12, 1, 5, 3), terms_supported(200, 2, 5, 3)
    (0, 2, 3)
    """
    return max((k for k in range(most + 1) if rows_for_terms(n_fit_parameters, folds, k) <= n_rows),
               default=0)


def few_rows(n_rows: int, n_fit_parameters: int, folds: int, supported: int, most: int,
             leaning: Sequence[tuple[str, float]] = (), z_needed: float | None = None
             ) -> dict[str, Any] | None:
    """The report's item when the rows support fewer terms than the search may add (None otherwise).

    With ``supported`` below ``most`` the search adds at most ``supported`` terms: no effect beyond them is
    claimed either way (the data cannot decide), and :func:`rows_for_terms` says how many rows would let
    the search weigh one more. ``leaning`` (label, held-out paired z) names the candidates the rows lean to
    that the intervals hold as rivals (:func:`calibrate.rivals.undecided_candidates`); with the step's
    ``z_needed``, the rows that would carry the first one's z over it (:func:`rows_to_settle`) are said too
    (``rows_to_settle`` stays the rows that would let the search weigh one more term).

    Examples
    --------
    >>> item = few_rows(8, 1, 4, 0, 3, [("humidity_meniscus on relative_humidity", 1.5)], 4.5)
    >>> item["rows_to_settle"], item["terms"], "about 72 rows drawn like these" in item["statement"]
    (9, ['humidity_meniscus on relative_humidity'], True)
    """
    if supported >= most:
        return None
    more = rows_for_terms(n_fit_parameters, folds, supported + 1)
    what = ("no term could be weighed" if supported == 0 else
            f"at most {supported} term{'s' if supported > 1 else ''} could be weighed")
    statement = (f"with {n_rows} rows {what} ({folds}-fold nested cross-validation, {n_fit_parameters} "
                 f"fitted parameter(s)): the data cannot decide whether any further effect is there, and "
                 f"none is claimed; about {more} rows would let the search weigh one more term")
    if leaning:
        label, z = leaning[0]
        statement += (f". The rows lean to {', '.join(name for name, _ in leaning)} (held-out loss lower "
                      f"than the model's without it, paired z {', '.join(f'{z:.2f}' for _, z in leaning)}"
                      f"), held as rivals in the intervals")
        if z_needed is not None and (rows := rows_to_settle(n_rows, z, z_needed)) is not None:
            statement += (f"; about {rows} rows drawn like these would carry {label} to the z of "
                          f"{z_needed:.2f} a term needs")
    return {
        "kind": "few_rows", "terms": [name for name, _ in leaning], "z": None, "z_needed": None,
        "rows_now": n_rows, "rows_to_settle": more, "where": None,
        "statement": f"{statement}. The intervals carry the small-sample allowance of so few rows",
    }


def _where(dataset: Dataset, term: Term, mu_with: np.ndarray, mu_without: np.ndarray,
           with_term=None, without_term=None, noise_std_log: float | None = None) -> dict[str, Any]:
    """Where the model with the term and the one without differ most along the term's main driver.

    With both models as callables (and the scatter of a measurement), the driver is scanned over the
    data's range and as much again on either side (:func:`calibrate.rivals.where_they_part`): ``range``
    spans the values where they differ by more than two standard deviations of a measurement and by
    at least half their largest difference (the largest difference's place when nowhere). Without
    them, ``range`` is the driver's range over the
    quarter of the rows where the two held-out predictions differ most.
    """
    driver = term.drivers[0]
    columns = dataset.columns()
    if driver not in columns:
        return located(dataset, {"driver": driver, "range": None, "data_range": None})
    x = np.asarray(columns[driver], dtype=float)
    data_range = [float(x.min()), float(x.max())]
    span = None
    if with_term is not None and without_term is not None and noise_std_log:
        part = where_they_part(without_term, with_term, dataset, driver, noise_std_log, _HALF)
        if part["differ"]:
            span = [min(r[0] for r in part["differ"]), max(r[1] for r in part["differ"])]
        elif part["at"] is not None:
            span = [part["at"], part["at"]]
    if span is None:
        difference = np.abs(np.log(mu_with / mu_without))
        count = max(int(np.ceil(_TOP_SHARE * x.size)), 1)
        top = np.argsort(-difference)[:count]
        span = [float(x[top].min()), float(x[top].max())]
    return located(dataset, {"driver": driver, "range": span, "data_range": data_range})


def _span(where: Mapping[str, Any], dataset: Dataset) -> str:
    if where["range"] is None:
        return ""
    where = in_sent_units(dataset, where)  # in the upload's unit
    lo, hi = where["range"]
    dlo, dhi = where["data_range"]
    at = f"{lo:.3g}" if lo == hi else f"{lo:.3g} to {hi:.3g}"
    return f"{where['driver']} {at} (data: {dlo:.3g} to {dhi:.3g})"


def _models(dataset: Dataset, fit_parameters, current_terms, current_values, term: Term, start, convention):
    """The model with and without ``term`` (refitted on the rows), as callables of columnar points."""
    names = _physics.PARAMETERS

    def model(declared, terms, values):
        def mu(points):
            inputs = {**dataset.fixed, **declared, **{k: v for k, v in points.items() if k in names}}
            conditions = {k: v for k, v in points.items() if k not in names}
            return mu_of(inputs, conditions, terms, values, convention=convention)
        return mu

    with np.errstate(all="ignore"):
        try:
            without = fit(dataset, fit_parameters, current_terms, start=start, start_terms=current_values,
                          precise=False, convention=convention)
            terms = (*current_terms, term)
            withit = fit(dataset, fit_parameters, terms, start=without.declared,
                         start_terms=without.term_values, precise=False, convention=convention)
        except ValueError:
            return None, None
    return (model(withit.declared, terms, withit.term_values),
            model(without.declared, tuple(current_terms), without.term_values))


def undecided(
    dataset: Dataset,
    selection: Selection,
    stability: Mapping[str, Any] | None = None,
    rivals: Sequence[Mapping[str, Any]] = (),
    fit_parameters: Sequence[str] = (),
    noise_std_log: float | None = None,
    convention: str = _physics.DEFAULT_CONVENTION,
) -> list[dict[str, Any]]:
    """What the data leave undecided, with where more rows would settle it.

    Parameters
    ----------
    dataset : Dataset
        The calibration data (all rows).
    selection : Selection
        The forward selection on (a subset of) them; its steps' scores are over ``selection.rows``.
    stability : mapping, optional
        :meth:`calibrate.select.NestedValidation.stability` of the chosen terms.
    rivals : sequence of mapping
        The report's rivals (``label``, ``where``, ``statement``; see :mod:`calibrate.rivals`).
    fit_parameters : sequence of str
        Declared parameters fitted (to refit a candidate left out, and scan where it would act).
    noise_std_log : float, optional
        Scatter of log μ of a measurement [1]; with it, where a term acts is scanned beyond the data.
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    list of dict
        ``kind`` (``near_threshold``, ``barely_chosen`` or ``rivals``), ``terms`` (labels), ``z`` and
        ``z_needed`` [1] (None for rivals), ``rows_now`` [1], ``rows_to_settle`` [1] (rows drawn like
        these that would carry z over the threshold, None when it does not apply), ``where``
        (``driver``, ``range`` and ``data_range`` in the driver's unit, or the rivals' scan) and
        ``statement`` in words.
    """
    searched = search_data(dataset, selection.rows)
    n = searched.n_points
    found: list[dict[str, Any]] = []
    for step in selection.steps:
        if step.chosen is None:
            close = close_calls(step)
            if close:
                # Named by the selection's own rule (a named law before a generic term that fits as
                # well), with every close candidate that fits as well within one standard error.
                best = preferred(searched, close)
                equal = [c for c in close if c is not best and within_one_se(c.loss, best.loss)]
                model = selection.model.full
                pair = _models(searched, fit_parameters, selection.terms, model.term_values, best.term,
                               model.declared, convention)
                where = _where(searched, best.term, best.oof_mu, step.current.oof_mu, *pair, noise_std_log)
                found.append(_near(best, step.z_needed, n, where, searched, equal))
            continue
        chosen = step.chosen
        if chosen.z <= step.z_needed + CLOSE_MARGIN:
            where = _where(searched, chosen.term, chosen.oof_mu, step.current.oof_mu)
            settle = rows_to_settle(n, chosen.z, step.z_needed + CLOSE_MARGIN)
            found.append({
                "kind": "barely_chosen", "terms": [chosen.term.label], "z": float(chosen.z),
                "z_needed": float(step.z_needed), "rows_now": n, "rows_to_settle": settle, "where": where,
                "statement": (f"{chosen.term.label} was added, but barely (held-out z = {chosen.z:.2f} "
                              f"against {step.z_needed:.2f} needed): about {settle} rows drawn like these "
                              f"would make it clear, fewer if placed at {_span(where, searched)}, "
                              f"where it acts most"),
            })
    if stability and selection.terms:
        folds, agreeing = int(stability.get("folds", 0)), int(stability.get("same_driver", 0))
        if folds and 2 * agreeing < folds:
            labels = [t.label for t in selection.terms]
            found.append({
                "kind": "barely_chosen", "terms": labels, "z": None, "z_needed": None, "rows_now": n,
                "rows_to_settle": None, "where": None,
                "statement": (f"only {agreeing} of {folds} outer folds chose the same driver(s) as all rows "
                              f"did ({', '.join(labels)}): the choice rests on a few rows, and more rows "
                              f"would settle it"),
            })
    for rival in rivals:
        found.append({
            "kind": "rivals", "terms": [rival["label"]], "z": None, "z_needed": None, "rows_now": n,
            "rows_to_settle": None, "where": list(rival.get("where", [])), "statement": rival["statement"],
        })
    return found


def _near(best: CandidateScore, z_needed: float, n: int, where: Mapping[str, Any], dataset: Dataset,
          equal: Sequence[CandidateScore] = ()) -> dict[str, Any]:
    settle = rows_to_settle(n, best.z, z_needed)
    statement = (f"the data cannot decide on {best.term.label}: held-out z = {best.z:.2f}, just short "
                 f"of the {z_needed:.2f} needed (on data with nothing to find the best candidate stays "
                 f"below about 2.2 in 99 % of cases); about {settle} rows drawn like these (now {n}) "
                 f"would settle it, fewer if placed at {_span(where, dataset)}, where it would act most")
    if equal:
        statement += f"; {_equals(best, equal)}"
    return {
        "kind": "near_threshold", "terms": [best.term.label, *(c.term.label for c in equal)],
        "z": float(best.z), "z_needed": float(z_needed), "rows_now": n, "rows_to_settle": settle,
        "where": where, "statement": statement,
    }


def _equals(best: CandidateScore, equal: Sequence[CandidateScore]) -> str:
    """Words for candidates that fit as well as ``best``, naming the drivers the data cannot tell apart.

    Examples
    --------
    >>> from microbearing.calibrate.candidates import DriftTerm, EffectTerm
    >>> law = CandidateScore(DriftTerm("viscosity_Pa_s", "arrhenius", "temperature_C"), 3, np.ones(2), 0.0,
    ...                      2.9, True, np.ones(2))
    >>> poly = CandidateScore(EffectTerm("generic_quadratic", ("speed_m_s",)), 3, np.ones(2), 0.0, 3.0,
    ...                       True, np.ones(2))
    >>> print(_equals(law, [poly]))  # doctest: +NORMALIZE_WHITESPACE
    generic_quadratic on speed_m_s fits as well (within one standard error): the data cannot tell
    temperature_C from speed_m_s as the driver; the named law is given first, before a generic term
    """
    labels = ", ".join(c.term.label for c in equal)
    words = f"{labels} fit{'s' if len(equal) == 1 else ''} as well (within one standard error)"
    main = best.term.drivers[0]
    others = list(dict.fromkeys(c.term.drivers[0] for c in equal if c.term.drivers[0] != main))
    if others:
        words += f": the data cannot tell {main} from {', '.join(others)} as the driver"
    if not best.term.generic and any(c.term.generic for c in equal):
        words += "; the named law is given first, before a generic term"
    return words

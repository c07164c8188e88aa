"""Sentences of a calibration report (:func:`calibrate.report.format_report`) about rivals, code-like
columns, drivers the data cannot tell apart and the domain rule, each written from the stages' results.

Values of a column are written in the unit the upload used (``speed [mm/s] 50 to 100``:
:attr:`calibrate.Dataset.headers`, read back through :mod:`physics.columns`); the numbers of the
report's fields stay in SI.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.physics.columns import unit_of

from .candidates import Term
from .data import Dataset
from .domain import DataCloud
from .fit import Z95
from .model import CalibratedModel
from .rivals import describe_rival, where_they_part
from .scores import within_one_se
from .select import Selection

__all__ = ["code_columns", "domain_report", "domain_words", "in_sent_units", "in_sent_words",
           "level_not_drift", "located", "rival_drivers", "rival_words", "with_headers"]


def rival_words(dataset: Dataset, model: CalibratedModel, rivals) -> list[dict[str, Any]]:
    """Each rival with where it parts from the model (over its driver, and the replaced term's)."""
    out = []
    for rival, alternative in zip(rivals, model.rival_models(), strict=True):
        other = rival.partner if rival.replaces is None else rival.replaces.drivers[0]
        drivers = dict.fromkeys(d for d in (rival.term.drivers[0], other) if d is not None)
        where = [located(dataset, where_they_part(model, alternative, dataset, d, model.noise_std_log))
                 for d in drivers]
        part = max(where, key=lambda w: w["largest_difference_log"] or 0.0)
        out.append({"label": rival.label, "label_as_sent": in_sent_words(dataset, rival.label),
                    "gap_se": rival.gap_se, "where": where,
                    "statement": in_sent_words(dataset, describe_rival(rival, in_sent_units(dataset, part)))})
    return out


def in_sent_words(dataset: Dataset, text: str) -> str:
    """Words (a term's label, a statement) with each column the upload sent under another header or unit
    named by that header, as the plots name it: ``thermal_shear_strength on temperature [degF]`` for
    ``... on temperature_K``; a header already in the words stays as it is. Numbers in the words are the
    writer's to give in the unit sent (:func:`in_sent_units`).

    >>> from microbearing.calibrate.tabular import read_rows
    >>> d, _ = read_rows([{"speed [mm/s]": 50, "load_N": 0.01, "balls": 4, "mu_measured": 0.01}])
    >>> in_sent_words(d, "stribeck on speed_m_s; over speed [mm/s] 10 to 100")
    'stribeck on speed [mm/s]; over speed [mm/s] 10 to 100'
    """
    headers = {name: reading.sent.strip() for name in dataset.headers
               if (reading := dataset.sent_reading(name)) is not None}
    return with_headers(text, headers)


def with_headers(text: str, headers: Mapping[str, str]) -> str:
    """Words with each column of ``headers`` (column -> its header as sent) named by its header; a header
    already in the words stays as it is.

    >>> with_headers("mu_pivot drifts with RH (linear); RH [%] 20 to 80", {"RH": "RH [%]"})
    'mu_pivot drifts with RH [%] (linear); RH [%] 20 to 80'
    """
    for name, header in headers.items():
        if header == name:
            continue
        pattern = re.compile(rf"{re.escape(header)}|(?<![\w]){re.escape(name)}(?![\w])")
        text = pattern.sub(lambda _match, header=header: header, text)
    return text


def in_sent_units(dataset: Dataset, part: Mapping[str, Any]) -> dict[str, Any]:
    """Where two models part (:func:`calibrate.rivals.where_they_part`, or where a term acts) with the
    driver named by its header as sent and its values (``range``, ``data_range``, ``differ``) in that unit,
    for words; as it is when the driver was sent in its own unit.

    >>> from microbearing.calibrate.tabular import read_rows
    >>> d, _ = read_rows([{"speed [mm/s]": 50, "load_N": 0.01, "balls": 4, "mu_measured": 0.01}])
    >>> in_sent_units(d, {"driver": "speed_m_s", "data_range": [0.01, 0.1], "differ": [[0.05, 0.1]]})
    {'driver': 'speed [mm/s]', 'data_range': [10.0, 100.0], 'differ': [[50.0, 100.0]]}
    """
    reading = dataset.sent_reading(part["driver"])
    if reading is None:
        return dict(part)
    out = {**part, "driver": reading.sent}
    if part.get("at") is not None:
        out["at"] = reading.sent_value(part["at"])
    for key in ("range", "data_range"):
        if part.get(key) is not None:
            out[key] = [reading.sent_value(v) for v in part[key]]
    if part.get("differ") is not None:
        out["differ"] = [[reading.sent_value(a), reading.sent_value(b)] for a, b in part["differ"]]
    return out


def located(dataset: Dataset, part: Mapping[str, Any]) -> dict[str, Any]:
    """Where two models part, or where a term acts (:func:`in_sent_units`' ``part``, values in the column's
    own unit), with that ``unit`` (:func:`physics.columns.unit_of`; None for a column without one, such as
    a run index) and ``as_sent``: the same in the unit and under the header the upload used, ``unit`` the
    one written there (None when the column was sent in its own unit).

    >>> from microbearing.calibrate.tabular import read_rows
    >>> d, _ = read_rows([{"speed [mm/s]": 50, "load_N": 0.01, "balls": 4, "mu_measured": 0.01}])
    >>> w = located(d, {"driver": "speed_m_s", "data_range": [0.01, 0.1], "at": 0.05})
    >>> w["unit"], w["as_sent"]["driver"], w["as_sent"]["unit"], w["as_sent"]["at"]
    ('m/s', 'speed [mm/s]', 'mm/s', 50.0)
    """
    reading = dataset.sent_reading(part["driver"])
    shown = {k: v for k, v in part.items() if k not in ("unit", "as_sent")}
    # the unit written in the header, or the column's own where the header renamed it only (temperature [K])
    as_sent = None if reading is None else {**in_sent_units(dataset, shown),
                                            "unit": reading.sent_unit or unit_of(part["driver"])}
    return {**shown, "unit": unit_of(part["driver"]), "as_sent": as_sent}


def code_columns(dataset: Dataset) -> list[str]:
    """A sentence per condition column that looks like integer codes of groups (the values 1..k or 0..k-1,
    3 <= k <= 20) and was not declared a factor: read as a number, it is a smooth driver."""
    words = []
    for name, values in dataset.conditions.items():
        distinct = np.unique(values)
        if 3 <= distinct.size <= 20 and np.all(distinct == np.round(distinct)) and (
                distinct[0] in (0.0, 1.0) and distinct[-1] - distinct[0] == distinct.size - 1):
            words.append(
                f"{name} holds the whole numbers {distinct[0]:.0f}..{distinct[-1]:.0f}: if they label groups "
                f"(specimens, builds, batches), declare {name} a factor (factors) so that the spread between "
                f"groups is fitted instead of a smooth effect of the number")
    return words


def rival_drivers(selection: Selection) -> list[str]:
    """Steps where a term on another driver fitted as well (within one standard error): the data cannot
    tell those drivers apart."""
    words = []
    for step in selection.steps:
        if step.chosen is None:
            continue
        main = step.chosen.term.drivers[0]
        rivals = [c for c in step.ranked if c.joint and c is not step.chosen and c.z > step.z_needed
                  and c.term.drivers[0] != main and within_one_se(c.loss, step.chosen.loss)]
        others = list(dict.fromkeys(c.term.drivers[0] for c in rivals))
        if others:
            words.append(
                f"{step.chosen.term.label} was chosen, but terms on {', '.join(others)} fitted as well "
                f"within one standard error: the data cannot tell {main} from {', '.join(others)} as the "
                f"driver")
    return words


def level_not_drift(terms: Sequence[Term], values: Sequence[Sequence[float]],
                    std: Sequence[Sequence[float]]) -> list[str]:
    """A sentence per chosen drift that fits its parameter's level (:attr:`DriftTerm.level`: the parameter
    is neither fitted nor fixed) while its coefficient's 95 % interval holds 0.

    Such a drift passes the search on its level: the parameter's default is wrong, and every drift of it on
    any column carries the same level and fits alike, so which column it names is a preference among equals
    (:func:`calibrate.scores.preferred`), not something the data show. The sentence says so, and how to fit
    the level alone (declare the parameter fitted).

    >>> from microbearing.calibrate.candidates import DriftTerm
    >>> t = DriftTerm("viscosity_Pa_s", "kelvin", "relative_humidity", {"reference": 1.0}, level=True)
    >>> print(level_not_drift([t], [[0.061, 0.0115]], [[0.19, 0.0033]])[0])  # doctest: +NORMALIZE_WHITESPACE
    viscosity_Pa_s drifts with relative_humidity (kelvin) is chosen for the level of viscosity_Pa_s, 0.0115
    Pa*s (12x its default 0.001), not for a change with relative_humidity: its kelvin_coefficient 0.061 [1]
    has a 95 % interval -0.311 to 0.433 that holds 0 (no change), so the data do not show that
    relative_humidity drives it; to fit the level alone, declare viscosity_Pa_s fitted
    >>> level_not_drift([t], [[0.9, 0.0115]], [[0.19, 0.0033]])
    []
    """
    words = []
    for term, value, sd in zip(terms, values, std, strict=True):
        if term.kind != "drift" or not term.level or not np.isfinite(sd[0]) or sd[0] <= 0:
            continue
        low, high = value[0] - Z95 * sd[0], value[0] + Z95 * sd[0]
        if low > 0 or high < 0:
            continue
        spec = physics.PARAMETERS[term.parameter]
        coefficient, default = term.parameter_names[0], float(spec.default)
        words.append(
            f"{term.label} is chosen for the level of {term.parameter}, {value[1]:.3g} {spec.unit} "
            f"({value[1] / default:.2g}x its default {default:.3g}), not for a change "
            f"with {term.driver}: its {coefficient} {value[0]:.3g} [{term.units[coefficient]}] has a 95 % "
            f"interval {low:.3g} to {high:.3g} that holds 0 (no change), so the data do not show that "
            f"{term.driver} drives it; to fit the level alone, declare {term.parameter} fitted")
    return words


def domain_report(dataset: Dataset, cloud: DataCloud | None,
                  ranges: Mapping[str, Sequence[float]] | None) -> dict[str, Any]:
    """The domain rule (:func:`domain_words`), its words naming columns as the upload did, and ``as_sent``:
    each column's range in the data (``ranges``, SI) under the header and in the unit the upload used
    (``{"load [mN]": {"column": "load_N", "range": [3, 30], "unit": "mN"}}``), for a form to fill."""
    domain = domain_words(cloud)
    as_sent = {}
    for name, ends in (ranges or {}).items():
        where = located(dataset, {"driver": name, "range": [float(v) for v in ends]})
        shown = where["as_sent"] or where
        as_sent[shown["driver"]] = {"column": name, "range": shown["range"], "unit": shown["unit"]}
    return {**domain, "summary": in_sent_words(dataset, domain["summary"]), "as_sent": as_sent}


def domain_words(cloud: DataCloud | None) -> dict[str, Any]:
    """The domain rule in words."""
    if cloud is None:
        return {"columns": [], "alpha": None, "summary": (
            "a point is in the domain when every input and condition lies within its range in the data "
            "(fewer than two columns vary, so the ranges are the data's shape)")}
    return {"columns": list(cloud.columns), "alpha": cloud.alpha, "summary": (
        f"a point is in the domain when every input and condition lies within its range in the data and "
        f"the point lies within the joint cloud of the rows in {', '.join(cloud.columns)} (scaled distance "
        f"to the 5th nearest row no more than {100 * (1 - cloud.alpha):.0f} % of the rows' own: about "
        f"{100 * cloud.alpha:.0f} % of new points drawn like the data fall outside); beyond it the "
        f"interval widens in proportion to the distance, and where columns move together it holds the "
        f"rivals by confounding (terms on the column the model does not read)")}

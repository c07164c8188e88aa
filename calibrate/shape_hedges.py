"""Named laws of a physics input a ``predict`` envelope extrapolates, hedged over their shape.

A calibration on data that do not reach the envelope in a physics input (the first data at 50-150 mm/s,
the envelope at 2-20 mm/s) may take no term in that input: a law of it is under the noise in the data
(a Stribeck rise 3 % at 50 mm/s). Runs in the envelope then show it, and the recalibration adds it with
its values fitted from them. The interval that recalibration reports carries the law's parameters; a law
whose value enters μ in closed form (:data:`physics.effects.VALUE_FORMS`) is pinned by runs anywhere in
its driver, but its shape parameter (a Stribeck speed, an exponent: a value form of None) is pinned only
by runs spread over the driver: runs at one speed leave the excess and the decay speed trading off
(bench/RESULTS.md, h60: the recalibration's log half-width 1.0-3.3x the promise's after 16 runs at 2 mm/s).

:func:`shape_hedges` builds, for each law the catalogue declares on such an input (:attr:`physics.effects.
Effect.fixed_drivers`, main driver the input) with one shape parameter, the calibrated model with that
law added at a few values of its shape over their plausible range, its other values the catalogue's
initial guess (the excess unknown: fitted with the rest), the covariance the information of the data taken
on all the parameters. The run search and the promise (:class:`calibrate.reported.ShapeHedge`) read the
widest of their intervals beside the model's: the runs spread where one value would leave the shape free,
and the promise covers what a recalibration that adds the law reports.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.physics.effects import EFFECTS, Effect

from .candidates import EffectTerm
from .model import CalibratedModel
from .reported import ShapeHedge

__all__ = ["SHAPE_VALUES", "curvature_hedges", "curvature_widths", "off_data_drivers", "off_data_inputs",
           "shape_hedges", "shape_widths"]

#: Values of a law's shape parameter hedged, evenly (geometrically for a positive range) over its range. [1]
SHAPE_VALUES = 5


def off_data_inputs(model: CalibratedModel, envelope: Mapping[str, np.ndarray]) -> dict[str, tuple]:
    """The physics inputs the envelope takes beyond the data's range (the model's domain), each with the
    span of the data and the envelope together, in the input's unit."""
    return {k: v for k, v in off_data_drivers(model, envelope).items() if k in physics.PARAMETERS}


def off_data_drivers(model: CalibratedModel, envelope: Mapping[str, np.ndarray]) -> dict[str, tuple]:
    """The columns (physics inputs and conditions) the envelope takes beyond the data's range (the model's
    domain), each with the span of the data and the envelope together, in the column's unit."""
    out = {}
    for name, (lo, hi) in (model.domain or {}).items():
        if name not in envelope:
            continue
        values = np.asarray(envelope[name], dtype=float)
        if values.size and (values.min() < lo or values.max() > hi):
            out[name] = (min(float(lo), float(values.min())), max(float(hi), float(values.max())))
    return out


def _shape_range(effect: Effect, index: int, span: tuple[float, float]) -> np.ndarray:
    """The hedged values of the effect's shape parameter: a scale of the driver within reach of the data
    and the envelope (``within_data``), else its plausible values, else its bounds."""
    parameter = effect.parameters[index]
    if parameter.within_data:
        lo, hi = span
    elif parameter.plausible is not None:
        lo, hi = parameter.plausible
    else:
        lo, hi = parameter.minimum, parameter.maximum
    lo, hi = max(float(lo), parameter.minimum), min(float(hi), parameter.maximum)
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return np.zeros(0)
    return np.geomspace(lo, hi, SHAPE_VALUES) if lo > 0 else np.linspace(lo, hi, SHAPE_VALUES)


def _laws_on(name: str, model: CalibratedModel) -> list[tuple[Effect, int]]:
    """The catalogue's named laws whose main driver is the input ``name`` and that have one shape
    parameter (a value form of None; of several, the one that is a scale of the driver, ``within_data``:
    ``stribeck_rise``'s decay speed), each with that parameter's index; not those the model has."""
    taken = {t.name for t, _ in model.terms if t.kind == "effect"}
    out = []
    for effect in EFFECTS.values():
        if effect.generic or effect.name in taken or effect.fixed_drivers[:1] != (name,):
            continue
        shapes = [i for i, form in enumerate(effect.value_forms) if form is None]
        if len(shapes) > 1:  # no closed form in the amplitude either (a rise by a factor): the driver's scale
            shapes = [i for i in shapes if effect.parameters[i].within_data]
        if len(shapes) == 1 and len(effect.value_forms) == len(effect.parameters):
            out.append((effect, shapes[0]))
    return out


def shape_hedges(response: Any, data: Mapping[str, np.ndarray] | None,
                 envelope: Mapping[str, np.ndarray]) -> list[tuple[str, CalibratedModel]]:
    """The calibrated model with each law of an input the envelope extrapolates added at each hedged value
    of its shape (see the module); empty when the envelope stays within the data in every physics input.

    Parameters
    ----------
    response : calibrate.experiments.CalibratedResponse
        The calibrated model as a design model (its fixed columns).
    data : mapping of str to numpy.ndarray, optional
        The data taken (columns); None: no hedge (their information is unknown).
    envelope : mapping of str to numpy.ndarray
        The envelope's points.

    Returns
    -------
    list of (str, CalibratedModel)
        A description and the model with the law added, its covariance the data's information inverted.
    """
    model = response.model
    inputs = off_data_inputs(model, envelope)
    if data is None or model.noise_std_log is None or not inputs:
        return []
    columns = response.points({k: np.asarray(v) for k, v in data.items()})
    with np.errstate(all="ignore"):
        mu = np.ravel(model(columns))  # the laws' initial guesses read the model's μ on the data
    out = []
    for name, span in inputs.items():
        for effect, index in _laws_on(name, model):
            drivers = effect.fixed_drivers
            if not all(d in columns for d in drivers) or not effect.accepts(columns, drivers):
                continue
            term = EffectTerm(effect.name, drivers, effect.constants(columns, drivers))
            x = effect.driver_values(columns, drivers)
            initial = [float(v) for v in effect.make_initial(mu, x, columns, term.constants)]
            shapes = _shape_range(effect, index, span)
            for shape in shapes:
                values = [*initial[:index], float(shape), *initial[index + 1:]]
                # the law's values unknown to their own size; its shape to its range
                spread = np.abs(np.array(values))
                spread[index] = 0.5 * (shapes[-1] - shapes[0])
                hedged = _with_information(response, replace(model, terms=[*model.terms, (term, values)],
                                                              rivals=[]), columns, spread)
                if hedged is not None:
                    out.append((f"{term.label} at {effect.parameters[index].name} {shape:.3g}", hedged))
    return out


def _with_information(response: Any, hedged: CalibratedModel, columns, spread: np.ndarray
                      ) -> CalibratedModel | None:
    """The hedged model with its covariance the inverse of the data's information on its parameters and a
    weak prior on the law's (standard deviations ``spread``): a combination of them no row moves (the
    excess and the shape on data where the law has decayed, or at one value of its driver) keeps its
    plausible spread instead of none."""
    design = type(response)(hedged, response.fixed)
    g = np.asarray(design.sensitivities(columns), dtype=float)
    sigma = np.asarray(design.scatter_sd(columns), dtype=float)
    b = g / sigma[:, None]
    if not np.all(np.isfinite(b)) or not np.all(spread > 0):
        return None
    information = b.T @ b
    k = spread.size
    information[-k:, -k:] += np.diag(1.0 / np.square(spread))
    return replace(hedged, covariance=np.linalg.pinv(information, hermitian=True))


def shape_widths(response: Any, data: Mapping[str, np.ndarray] | None, envelope: Mapping[str, np.ndarray],
                 candidates: Mapping[str, np.ndarray], planned: Mapping[str, np.ndarray] | None
                 ) -> list[ShapeHedge]:
    """The reported widths (:class:`calibrate.reported.ShapeHedge`) of :func:`shape_hedges`' models over
    the candidates and the envelope, for the run search and the promise of ``predict``."""
    return _widths(response, shape_hedges(response, data, envelope), candidates, envelope, planned)


def _widths(response: Any, hedges: list[tuple[str, CalibratedModel]], candidates: Mapping[str, np.ndarray],
            envelope: Mapping[str, np.ndarray], planned: Mapping[str, np.ndarray] | None) -> list[ShapeHedge]:
    """The hedged models' reported widths over the candidates and the envelope, centred on the model."""
    return [ShapeHedge(type(response)(m, response.fixed), candidates, envelope, planned) for _, m in hedges]


#: The generic law a ``predict`` search hedges on a column its envelope extrapolates. [1]
CURVATURE_LAW = "generic_quadratic"
#: The prior standard deviation of its coefficients, in log μ per unit of the span's standardized column:
#: weak (a bend of up to a factor e over the span), so that the data and the runs pin it, not the prior. [1]
CURVATURE_PRIOR_SD = 1.0


def curvature_hedges(response: Any, data: Mapping[str, np.ndarray] | None,
                     envelope: Mapping[str, np.ndarray]) -> list[tuple[str, CalibratedModel]]:
    """The calibrated model with a potential curvature added in each column (a physics input or a
    condition) the envelope extrapolates (DuMouchel and Jones 1994, *A simple Bayesian modification of
    D-optimal designs to reduce dependence on an assumed model*): a :data:`CURVATURE_LAW` over the
    envelope's span of the column, continued along its tangent towards the data, its coefficients zero with
    a weak prior (:data:`CURVATURE_PRIOR_SD`), its covariance the data's information with that prior [1]:
    the width a recalibration reports if it keeps a generic bend where the model is used.

    Runs that pin the model's own parameters, or refute its rivals, may all sit at one value of the column
    (a run-in's steady level at the envelope's far end; a power law in load at the largest load); a law
    the catalogue lacks, or a generic one a recalibration adds, then bends freely between those runs and
    the data (bench/plans_promise.py: cycles lab 0, 16 runs at 50000 cycles, the recalibration kept a
    generic quadratic and reported 3.3x the promised half-width; load lab 1, 16 runs at 30 mN, 1.6x main's
    half-width). The search reads these widths beside the model's so that its runs pin a bend too; the
    promise does not (a recalibration adds no term the runs do not show)."""
    model = response.model
    drivers = off_data_drivers(model, envelope)
    if data is None or not drivers:
        return []
    columns = response.points({k: np.asarray(v) for k, v in data.items()})
    effect = EFFECTS[CURVATURE_LAW]
    out = []
    for name in drivers:
        if name not in columns:
            continue
        span = np.array([np.min(envelope[name]), np.max(envelope[name])], dtype=float)
        term = EffectTerm(effect.name, (name,), effect.constants({name: span}, (name,)))
        values = [0.0] * len(effect.parameters)
        spread = np.full(len(values), CURVATURE_PRIOR_SD)
        hedged = _with_information(response, replace(model, terms=[*model.terms, (term, values)], rivals=[]),
                                   columns, spread)
        if hedged is not None:
            out.append((f"{term.label} over {span[0]:.3g}-{span[1]:.3g}", hedged))
    return out


def curvature_widths(response: Any, data: Mapping[str, np.ndarray] | None, envelope: Mapping[str, np.ndarray],
                     candidates: Mapping[str, np.ndarray], planned: Mapping[str, np.ndarray] | None
                     ) -> list[ShapeHedge]:
    """The reported widths of :func:`curvature_hedges`' models over the candidates and the envelope, for
    the run search of ``predict`` (not its promise)."""
    return _widths(response, curvature_hedges(response, data, envelope), candidates, envelope, planned)

"""Surrogates in the service: train (a job), store as data, view, predict, Sobol' indices, load.

A surrogate is stored as a model of kind ``"surrogate"``: its public result and the fitted
estimator as JSON data (:func:`surrogate.to_dict`: training points, hyperparameters, space,
package version and physics convention), never pickle. A surrogate learns the physics or a
calibrated model (``"calibrated:<id>"``, resolved by :func:`service.models.resolve`).
:func:`load_surrogate` rebuilds the estimator of a stored id (a refit of its Gaussian process, cubic
in n_train; the store keeps the last few, :meth:`service.store.Store.rebuilt`), from which
:func:`service.models.resolve` makes the :class:`~service.models.SurrogateModel` of a
``"surrogate:<id>"`` reference; :func:`load_source_model` gives the model a surrogate stands for.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from microbearing import physics, surrogate
from microbearing.calibrate.domain import outside_law_domains
from microbearing.optimize import physics_model
from microbearing.physics.slips import input_slips
from microbearing.surrogate import GaussianProcessSurrogate, Space
from microbearing.surrogate.metrics import quality_warnings
from microbearing.surrogate.persist import version_warning

from .calibrations import read_conditions, with_conditions
from .models import CalibratedPhysicsModel, resolve
from .problems import ProblemError, pointer_at, validation_problem
from .schemas.surrogates import SurrogateRequest
from .store import Store, StoredModel, utc_now

__all__ = ["KIND", "MODEL_PREFIX", "SENSITIVITY_N", "delete_stored", "load_source_model", "load_stored",
           "load_surrogate", "predict", "prepare_training", "sensitivity", "surrogate_view",
           "surrogate_views", "train_surrogate"]

KIND = "surrogate"
MODEL_PREFIX = "surrogate:"
_HELD_OUT_POINTS = 1024
_HELD_OUT_SEED = 987_654_321
#: Least and most base sample size of the Sobol' indices (powers of 2). [1] The 95 % BCa intervals
#: (scipy's bootstrap) jackknife the n samples at once, so memory grows as n squared: a peak of
#: 424 MB at n = 4096, 110 MB at 2048 (tracemalloc, 2 dimensions); n = 65,536 asked for 32 GiB and
#: failed with a 500 (found by schemathesis' stateful phase), so n stops at 4096, the default.
SENSITIVITY_N = (256, 4096)
# Points on which a calibrated model is checked before its training job is accepted. [1]
_PROBE_POINTS = 16

MuModel = Callable[[Mapping[str, Any]], Any]


def _space_problem(exc: ValueError) -> ProblemError:
    """A :class:`surrogate.Space` refusal in the request's words (its ``space`` is the Space's bounds),
    pointing at the input it names."""
    text = str(exc)
    named = re.match(r"(bounds|fixed)\['(\w+)'\] (.*)", text)
    both = re.match(r"(\w+) cannot be both a dimension", text)
    if named is not None:
        pointer = pointer_at("/space" if named.group(1) == "bounds" else "/fixed", named.group(2))
        text = named.group(3)
    elif both is not None:
        pointer = pointer_at("/fixed", both.group(1))
    else:
        pointer = "/fixed" if text.startswith("fixed") else "/space"
    text = text.replace("parameter of physics.PARAMETERS", "physics input").replace("bounds", "space")
    return validation_problem([{"pointer": pointer, "detail": text}])


def _learned_model(store: Store, body: SurrogateRequest) -> tuple[MuModel | None, str, dict[str, Any]]:
    """The model a request learns and its convention, or a 404 / 422 problem.

    Parameters
    ----------
    store : Store
        Where calibrations are kept.
    body : SurrogateRequest
        Its ``model``, ``conditions`` and ``convention``.

    Returns
    -------
    mu_model : callable or None
        ``mu_model(points) -> mu`` [1] of a calibrated model with the request's conditions
        (:func:`service.calibrations.with_conditions`); None for the physics.
    convention : str
        The request's convention for the physics, else the calibrated model's.
    fixed : dict
        Physics values the calibration fixed (e.g. ``balls`` for data of one bearing), in their
        units; empty for the physics.
    """
    if body.model == "physics":
        if body.conditions:
            raise validation_problem([{"pointer": "/conditions", "detail": "condition columns are read by "
                                       "calibrated models only"}])
        return None, str(body.convention), {}
    calibrated = resolve(store, body.model, kinds=("physics", "calibrated"))
    if "convention" in body.model_fields_set and str(body.convention) != calibrated.convention:
        raise validation_problem([{"pointer": "/convention", "detail": f"the model {body.model} was "
                                   f"calibrated with convention {calibrated.convention!r}; omit convention"}])
    mu_model = with_conditions(calibrated, body.conditions)
    if isinstance(calibrated, CalibratedPhysicsModel):  # a law's domain, at the condition as sent
        sent = read_conditions(calibrated, body.conditions)
        outside = outside_law_domains(calibrated.calibrated.terms, dict(sent))
        if outside:
            raise validation_problem([{"pointer": pointer_at("/conditions", sent.key(name)),
                                       "detail": sent.as_sent(name, detail)}
                                      for name, detail in outside.items()])
    return mu_model, calibrated.convention, dict(calibrated.fixed)


def _build_space(body: SurrogateRequest, convention: str, defaults: Mapping[str, Any]) -> Space:
    """The :class:`surrogate.Space` of a request, or a 422 problem naming the field.

    ``defaults`` (a calibrated model's fixed values) hold the inputs that are neither a
    dimension nor in the request's ``fixed``.
    """
    bounds = {name: tuple(pair) for name, pair in body.space.model_dump(exclude_none=True).items()}
    fixed = {**{k: v for k, v in defaults.items() if k not in bounds},
             **body.fixed.model_dump(exclude_none=True)}
    try:
        return Space(bounds, fixed, convention=convention)
    except ValueError as exc:
        raise _space_problem(exc) from None


def _probe(space: Space, mu_model: MuModel) -> None:
    """422 unless the model answers a finite, positive μ on a small design of the space."""
    X = surrogate.design(space, _PROBE_POINTS, "sobol", seed=0)
    try:
        with np.errstate(all="ignore"):
            mu = space.evaluate(X, mu_model)
    except ValueError as exc:
        raise validation_problem([{"pointer": "/conditions", "detail": str(exc)}]) from None
    if not np.all(np.isfinite(mu) & (mu > 0)):
        raise validation_problem([{"pointer": "/conditions", "detail": "the calibrated model's mu is not "
                                   "finite and positive over the space at these conditions"}])


def prepare_training(store: Store, body: SurrogateRequest) -> tuple[Space, MuModel | None]:
    """Check a training request before its job is accepted.

    Parameters
    ----------
    store : Store
        Where calibrations are kept.
    body : SurrogateRequest
        The request.

    Returns
    -------
    space : surrogate.Space
        Dimensions and fixed values (a calibrated model's fixed values where the request sets none).
    mu_model : callable or None
        ``mu_model(points) -> mu`` [1] of the calibrated model to learn, with the request's
        conditions, checked finite and positive on a small design of the space; None for the physics.

    Raises
    ------
    ProblemError
        404 for an unknown calibrated model; 422 naming the field for a bad space, fixed value,
        convention or condition.
    """
    mu_model, convention, defaults = _learned_model(store, body)
    space = _build_space(body, convention, defaults)
    if mu_model is not None:
        _probe(space, mu_model)
    return space, mu_model


def source_domain_warnings(store: Store, body: SurrogateRequest, space: Space) -> list[str]:
    """Where the space (its dimensions' ranges, fixed values and the request's conditions) leaves the data
    of the calibrated model it learns (its declared ``domain``, each column's [min, max]): one sentence per
    column (empty for the physics, or inside the data). There the model extrapolates, and the surrogate's
    interval, its own approximation error, says nothing of the model's uncertainty."""
    if body.model == "physics":
        return []
    model = resolve(store, body.model, kinds=("physics", "calibrated"))
    domain = model.calibrated.domain or {}
    spans = {name: (float(low), float(high)) for name, low, high in zip(space.names, space.lower, space.upper,
                                                                        strict=True)}
    spans.update({name: (float(v), float(v)) for name, v in space.fixed.items()
                  if not isinstance(v, bool) and name not in spans})
    spans.update({name: (float(v), float(v)) for name, v in read_conditions(model, body.conditions).items()
                  if not isinstance(v, str)})
    words = []
    for name, (low, high) in spans.items():
        if name not in domain or (domain[name][0] <= low and high <= domain[name][1]):
            continue
        unit = physics.unit_suffix(name)
        asked = f"{low:g}{unit}" if low == high else f"[{low:g}, {high:g}]{unit}"
        words.append(f"{name} {asked} reaches outside the data of {body.model}, [{domain[name][0]:g}, "
                     f"{domain[name][1]:g}]{unit}: there the calibrated model extrapolates and the "
                     "surrogate's interval is its own approximation error, not the model's uncertainty")
    return words


def input_warnings(body: SurrogateRequest, space: Space) -> list[str]:
    """The unit slips the space's ends and fixed values look like (:func:`physics.slips.input_slips`: a
    speed above 10 m/s as mm/s), in /v1/friction's words, each judged as its key was sent; the surrogate
    learns the space as asked."""
    ends = zip(space.names, space.lower, space.upper, strict=True)
    inputs = {**space.fixed, **{name: np.array([low, high], dtype=float) for name, low, high in ends}}
    sent = {**body.fixed.renamed, **body.space.renamed}
    return input_slips(inputs, sent)


def train_surrogate(store: Store, space: Space, body: SurrogateRequest,
                    progress: Callable[[float], None] | None = None,
                    mu_model: MuModel | None = None) -> dict[str, Any]:
    """Train, measure on held-out evaluations of the model, store, and return the public result.

    Parameters
    ----------
    store : Store
        Where the surrogate is kept.
    space : surrogate.Space
        Dimensions and fixed values.
    body : SurrogateRequest
        Budget, target, design, adaptivity and seed.
    progress : callable, optional
        Fraction done, 0..1 (a job's progress, which also checks cancellation).
    mu_model : callable, optional
        The model to learn (:func:`prepare_training`); None for the physics.

    Returns
    -------
    dict
        The :class:`~service.schemas.surrogates.SurrogateResult` as JSON data.
    """
    start = time.perf_counter()
    plan = surrogate.SamplingPlan(design_method=str(body.design), adaptive=body.adaptive)
    fit = surrogate.fit_adaptive(space, budget=body.budget, target_relative_error=body.target_relative_error,
                                 plan=plan, seed=body.seed,
                                 progress=None if progress is None else (lambda f: progress(0.95 * f)),
                                 mu_model=mu_model, validation_points=body.validation_points)
    seconds = time.perf_counter() - start
    # said with the result and on every prediction, as the calibrated data's domain is
    outside = input_warnings(body, space) + source_domain_warnings(store, body, space)
    metrics = surrogate.holdout_metrics(fit.model, n_test=_HELD_OUT_POINTS, seed=_HELD_OUT_SEED,
                                        mu_model=mu_model)
    data = surrogate.to_dict(fit.model)
    space_data = space.to_dict()
    result = {
        "space": space_data["bounds"], "fixed": space_data["fixed"], "scales": space_data["scales"],
        "features": space.feature_names(fit.model.features), "budget": body.budget,
        "n_train": fit.n_train, "stop_reason": fit.stop_reason, "metrics": metrics, "history": fit.history,
        "kernel": data["gp"]["kernel"], "fit_seconds": seconds, "convention": data["convention"],
        "package_version": data["package_version"], "created_at": utc_now(),
        "model": body.model, "conditions": dict(body.conditions or {}),
        "target_relative_error": body.target_relative_error,
        "variance_calibration": fit.model.variance_calibration_, "std_scale": fit.model.std_scale_,
        "calibration_points": fit.model.calibration_points_, "radius_scales": data["radius_scales"],
        "validation_points": fit.validation_points,
        "source_warnings": outside,
    }
    surrogate_id = store.save_model(KIND, {"result": result, "model": data}, {},
                                    name=f"{len(space.names)}-D, {fit.n_train} evaluations")
    if progress is not None:
        progress(1.0)
    return surrogate_view(surrogate_id, {"result": result})


def _warnings(result: Mapping[str, Any]) -> list[str]:
    # Compared with the running version on every view: the service may have been upgraded since.
    version = version_warning(result.get("package_version"))
    return (quality_warnings(result) + list(result.get("source_warnings") or [])
            + ([] if version is None else [version]))


def surrogate_view(surrogate_id: str, metadata: Mapping[str, Any]) -> dict[str, Any]:
    """The public view of a stored surrogate (its result, reference and warnings), JSON-ready.

    Parameters
    ----------
    surrogate_id : str
        Its id.
    metadata : mapping
        Its stored metadata (``result``).

    Returns
    -------
    dict
        The :class:`~service.schemas.surrogates.SurrogateResult` as JSON data.
    """
    result = metadata["result"]
    # The ends of a whole-number dimension as whole numbers (stored as floats), so that the space can
    # be sent back as points to predict at: a column of balls takes 4, not 4.0.
    space = {name: [int(end) if physics.PARAMETERS[name].kind == "int" else end for end in ends]
             for name, ends in result["space"].items()}
    # Surrogates stored before models other than the physics could be learned lack model and conditions.
    # The calibrated model's domain warnings are among its warnings (stored apart: said on every prediction).
    shown = {key: value for key, value in result.items() if key != "source_warnings"}
    return {"id": surrogate_id, "model_id": MODEL_PREFIX + surrogate_id, "model": "physics", "conditions": {},
            **shown, "space": space, "warnings": _warnings(result)}


def surrogate_views(store: Store) -> list[dict[str, Any]]:
    """The view (:func:`surrogate_view`) of every stored surrogate the caller may see, newest first."""
    return [surrogate_view(row["id"], row["metadata"]) for row in store.list_models(KIND)]


def load_stored(store: Store, surrogate_id: str) -> StoredModel:
    """The stored surrogate of an id, or a 404 problem."""
    stored = store.load_model(surrogate_id)
    if stored is None or stored.kind != KIND:
        raise ProblemError(404, f"There is no surrogate {surrogate_id!r}.")
    return stored


def delete_stored(store: Store, surrogate_id: str) -> None:
    """Delete a stored surrogate (and its rebuilt estimator), or a 404 problem.

    Of concurrent deletions of one surrogate, one deletes it and the others answer 404.
    """
    if not store.has_model(surrogate_id, KIND) or not store.delete_model(surrogate_id):
        raise ProblemError(404, f"There is no surrogate {surrogate_id!r}.")


def load_surrogate(store: Store, surrogate_id: str) -> GaussianProcessSurrogate:
    """The fitted surrogate of a stored id (rebuilt from its data, kept by the store), or a 404 problem."""
    model = store.rebuilt(surrogate_id, KIND, lambda stored: surrogate.from_dict(stored.metadata["model"]))
    if model is None:
        raise ProblemError(404, f"There is no surrogate {surrogate_id!r}.")
    return model


def _refuse_unread_points(space: Any, points: Mapping[str, Any],
                          sent_as: Callable[[str], tuple[str, Any] | None]) -> None:
    """422 naming each input a prediction cannot answer for: an empty list, or a value other than the one
    the surrogate was trained at for an input that is not one of its dimensions (it does not read it:
    its answer would be the trained value's)."""
    trained = space.held_values()
    errors = []
    for name, value in points.items():
        key = (sent_as(name) or (name,))[0]
        column = np.atleast_1d(np.asarray(value, dtype=float))
        if column.size == 0:
            errors.append({"pointer": pointer_at("/points", key), "detail": "a list must not be empty"})
        elif name in trained and np.any(column != float(trained[name])):
            other = float(column[column != float(trained[name])][0])
            errors.append({"pointer": pointer_at("/points", key),
                           "detail": f"the surrogate {space.unread_words(name, other)}"})
    if errors:
        raise validation_problem(errors)


def predict(store: Store, surrogate_id: str, points: Mapping[str, Any],
            sent_as: Callable[[str], tuple[str, Any] | None] = lambda name: None) -> dict[str, Any]:
    """Predicted μ with its 95 % interval at columnar points, flagging points outside the space.

    Parameters
    ----------
    store : Store
        Where surrogates are kept.
    surrogate_id : str
        The surrogate.
    points : mapping of str to float or list of float
        Every dimension of the surrogate, in its unit; scalars broadcast.
    sent_as : callable, optional
        An input's key and value as sent when it was renamed (``load [mN]``), for a refusal's pointer.

    Returns
    -------
    dict
        The :class:`~service.schemas.surrogates.PredictResponse` as JSON data: ``mu``,
        ``mu_lower``, ``mu_upper`` [1], ``outside_space`` and ``warnings``.

    Raises
    ------
    ProblemError
        404 for an unknown surrogate, 422 (``/points``) for points it cannot read.
    """
    result = load_stored(store, surrogate_id).metadata["result"]
    model = load_surrogate(store, surrogate_id)
    _refuse_unread_points(model.space, points, sent_as)
    try:
        prediction = model.predict_points(points)
    except ValueError as exc:
        raise validation_problem([{"pointer": "/points", "detail": str(exc)}]) from None
    outside = int(np.count_nonzero(prediction.outside_space))
    extrapolated = [] if not outside else [
        f"{outside} of {prediction.outside_space.size} points lie outside the trained space: their "
        f"intervals do not apply"]
    return {"mu": prediction.mu.tolist(), "mu_lower": prediction.mu_lower.tolist(),
            "mu_upper": prediction.mu_upper.tolist(), "outside_space": prediction.outside_space.tolist(),
            "warnings": _warnings(result) + extrapolated}


def sensitivity(store: Store, surrogate_id: str, n: int) -> dict[str, Any]:
    """First-order and total Sobol' indices of μ over a surrogate's space, with 95 % intervals.

    Parameters
    ----------
    store : Store
        Holds the surrogate (rebuilt through :func:`load_surrogate`).
    surrogate_id : str
        Its id.
    n : int
        Base sample size, a power of 2 within :data:`SENSITIVITY_N`. [1]

    Returns
    -------
    dict
        The :class:`~service.schemas.surrogates.SensitivityResponse` as JSON data.

    Raises
    ------
    ProblemError
        404 for an unknown surrogate.
    """
    model = load_surrogate(store, surrogate_id)
    indices = surrogate.sobol_indices(model.predict, model.space, n=n, seed=0).to_dict()
    return {
        **{key: indices[key] for key in ("first_order", "total_order", "first_order_interval",
                                         "total_order_interval")},
        "confidence_level": 0.95, "n": n,
        "distribution": "independent inputs, uniform in the design's unit cube (log-uniform on "
                        "log-scaled dimensions, integers rounded)",
    }


def load_source_model(store: Store, model: str, pointer: str = "/model") -> tuple[MuModel, str]:
    """The model a ``"surrogate:<id>"`` stands for, to verify what is found on the surrogate.

    Parameters
    ----------
    store : Store
        Where surrogates and calibrations are kept.
    model : str
        ``"surrogate:<id>"``.
    pointer : str
        JSON pointer of the reference in the request, for errors.

    Returns
    -------
    mu_model : callable
        ``points -> mu`` [1] of the physics (the surrogate's convention) or of the calibrated model
        it learned, with the conditions it was trained at.
    name : str
        ``"physics"`` or ``"calibrated:<id>"``.

    Raises
    ------
    ProblemError
        422 for a malformed reference; 404 for an unknown surrogate, or when the calibrated model
        it learned has been deleted.
    """
    learned = resolve(store, model, pointer, kinds=("surrogate",))
    result = load_stored(store, learned.reference.removeprefix(MODEL_PREFIX)).metadata["result"]
    source = result.get("model", "physics")
    if source == "physics":
        return physics_model(result["convention"]), source
    return with_conditions(resolve(store, source, kinds=("physics", "calibrated")),
                           result.get("conditions")), source

"""Optimizations in the service: a request parsed, its model resolved, planned and run.

The design problem and its envelope come from :func:`optimize.plan.plan_design` (the request's plain
values, :class:`optimize.plan.DesignRequest`); this module resolves the model the request names, binds
its conditions, picks the method, runs it, and turns errors into problems.

``model="physics"`` is solved by :func:`optimize.optimize_design` (a certified
global optimum); ``calibrated:<id>`` and ``surrogate:<id>`` by
:func:`optimize.optimize_model` (a local optimum), a surrogate's design verified by
the model it stands for. A request with an operating envelope (a speed or condition range, a
tolerance, or the objective ``mu_upper``) is solved by :func:`optimize.robust.optimize_robust`
(the worst case over the envelope, with its proof), a surrogate's design verified over the envelope
by the model it stands for (the physics' worst case there exact, at the envelope's worst vertex).
Infeasible problems become a 422 problem whose ``errors`` point at the conflicting limits and
bounds: at once on every model when the limits that do not depend on μ conflict, else (a
friction-force limit no design of a surrogate or calibrated model meets) as the job's problem.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from concurrent.futures import Executor
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

from microbearing.calibrate.domain import outside_law_domains
from microbearing.optimize import (
    DesignProblem,
    InfeasibleDesignError,
    ParetoFront,
    optimize_design,
    optimize_model,
    pareto_front,
)
from microbearing.optimize.plan import (
    DesignRequest,
    PlanError,
    check_request,
    plan_design,
    verify_over_envelope,
)
from microbearing.optimize.robust import Envelope, optimize_robust
from microbearing.physics.model import Model
from microbearing.physics.slips import input_slips

from .calibrations import ReadConditions, interval_at, read_conditions, shown, with_conditions
from .executor import map_chunks
from .models import CalibratedPhysicsModel, resolve
from .problems import ProblemError, pointer_at, validation_problem
from .schemas.friction import InputKeys
from .schemas.optimizations import OptimizationRequest
from .store import Store
from .surrogates import load_source_model

__all__ = ["INFEASIBLE_TYPE", "SYNC_MAX_BALL_COUNTS", "OptimizationPlan", "infeasible_problem", "pareto_png",
           "prepare", "run"]

#: Physics requests with at most this many ball counts (and no Pareto front) answer at once. [1]
SYNC_MAX_BALL_COUNTS = 40
INFEASIBLE_TYPE = "urn:microbearing:problem:infeasible-design"
_BOUND_POINTERS = {"balls": "/bounds/balls", "balls_min": "/bounds/balls", "balls_max": "/bounds/balls",
                   "groove_angle_deg_min": "/bounds/groove_angle_deg",
                   "groove_angle_deg_max": "/bounds/groove_angle_deg",
                   "load_N_min": "/bounds/load_N", "load_N_max": "/bounds/load_N"}


@dataclass(frozen=True)
class OptimizationPlan:
    """A validated request, ready to run.

    Attributes
    ----------
    problem : DesignProblem
        The design problem.
    model : str
        The model reference of the request.
    mu_model : callable or None
        μ model for the local method; None for the certified physics.
    starts : int
        Starts per ball count of the local method. [1]
    pareto : dict or None
        ``{"objective", "points"}`` when a front is asked for.
    synchronous : bool
        Whether to answer at once rather than as a job.
    source_model : callable or None
        For a surrogate, the model it stands for (physics or calibrated), which verifies the
        design found on it; None otherwise.
    source_name : str or None
        Its name (``"physics"`` or ``"calibrated:<id>"``).
    interval : callable or None
        For a calibrated model, the 95 % interval and domain check at a design point
        (:func:`service.calibrations.interval_at`).
    envelope : Envelope or None
        The operating envelope of a robust design (:func:`optimize.robust.optimize_robust`); None for
        a design at one point.
    objective : str
        ``"mu"`` or ``"mu_upper"`` (robust designs).
    resolved : Model or None
        The model a robust design runs on (None for the physics).
    time_limit_s : float
        No new round of a robust design's outer approximation after this time. [s]
    readings : mapping
        How each condition was read from its key as sent (:class:`physics.columns.Reading`), for the
        worst case's domain warnings in the request's units.
    tolerance_readings : mapping
        How each tolerance was read from its key as sent (``groove angle [rad]``), for the result's
        ``tolerances_as_sent``.
    design_readings : mapping
        How each design variable was read from its key as sent (bounds, or a fixed load: ``load [gf]``),
        for every design's ``design_as_sent`` and the worst case's groove angle as sent.
    """

    problem: DesignProblem
    model: str
    mu_model: Callable[[Mapping[str, Any]], Any] | None
    starts: int
    pareto: dict[str, Any] | None
    synchronous: bool
    source_model: Callable[[Mapping[str, Any]], Any] | None = None
    source_name: str | None = None
    interval: Callable[[Mapping[str, Any]], dict[str, Any]] | None = None
    envelope: Envelope | None = None
    objective: str = "mu"
    resolved: Model | None = None
    time_limit_s: float = 60.0
    input_warnings: tuple[str, ...] = ()
    readings: Mapping[str, Any] = field(default_factory=dict)
    tolerance_readings: Mapping[str, Any] = field(default_factory=dict)
    design_readings: Mapping[str, Any] = field(default_factory=dict)


def _request(body: OptimizationRequest) -> DesignRequest:
    """The request's plain values (:class:`optimize.plan.DesignRequest`)."""
    b = body.bounds
    return DesignRequest(
        balls=tuple(b.balls), groove_angle_deg=tuple(b.groove_angle_deg),
        load_N=None if b.load_N is None else tuple(b.load_N), fixed=body.fixed.model_dump(exclude_none=True),
        speed_m_s=body.speed_m_s, constraints=body.constraints.model_dump(),
        conditions=dict(body.conditions or {}),
        tolerances={} if body.tolerances is None else body.tolerances.model_dump(exclude_none=True),
        objective=body.objective, model=body.model, convention=str(body.convention),
        pareto=body.pareto is not None, readings=_readings(body))


def _readings(body: OptimizationRequest) -> dict[str, Any]:
    """How the request's speed, conditions, design bounds and tolerances (``tolerances.<name>``) were sent
    (:class:`physics.columns.Reading` by column), for the words of a proof in the request's keys and units."""
    speed = {**body.fixed.readings, **body.readings}.get("speed_m_s")
    design = {name: r for name, r in _design_readings(body).items() if name in ("groove_angle_deg", "load_N")}
    tolerances = {} if body.tolerances is None else body.tolerances.readings
    return {**design, **ReadConditions.of(body.conditions).readings,
            **({} if speed is None else {"speed_m_s": speed}),
            **{f"tolerances.{name}": r for name, r in tolerances.items()}}


def _design_readings(body: OptimizationRequest) -> dict[str, Any]:
    """How the design variables were sent: the bounds' keys, and a load given in ``fixed`` (``load [gf]``)."""
    load = body.fixed.readings.get("load_N")
    return {**body.bounds.readings, **({} if load is None else {"load_N": load})}


def _plan_problem(error: PlanError, body: OptimizationRequest) -> ProblemError:
    """The 422 problem of a request that is no design problem, each field named by its JSON pointer: a
    condition by its key and value as sent when :func:`read_conditions` read them, a physics input the
    schema renamed (``bounds.load_N`` sent as ``load [mN]``) likewise."""
    sent = ReadConditions.of(body.conditions)
    items = []
    for name, detail in error.errors:
        field, _, column = name.partition(".")
        if field == "conditions" and column:
            items.append({"pointer": pointer_at("/conditions", sent.key(column)),
                          "detail": sent.as_sent(column, detail)})
            continue
        *path, last = name.split(".") if name else [""]
        owner = body
        for part in path:
            owner = getattr(owner, part, None)
        renamed = owner.sent_as(last) if isinstance(owner, InputKeys) else None
        if renamed is None:
            items.append({"pointer": "/" + name.replace(".", "/") if name else "", "detail": detail})
        else:
            key, value = renamed
            items.append({"pointer": pointer_at("/" + "/".join(path) if path else "", key),
                          "detail": f"{detail} (sent as {key}: {shown(value)}, read as {last})"})
    return validation_problem(items)


def _bound(model: Model, body: OptimizationRequest) -> tuple[Callable, Callable | None]:
    """A stored model's μ model with the request's conditions bound, and its interval at a point."""
    # A range is checked by name here; its values are taken apart by the envelope.
    read = ReadConditions.of(body.conditions)
    points = {name: value[0] if isinstance(value, list) else value
              for name, value in (body.conditions or {}).items()}
    if points and read:  # keys and values as sent kept: read_conditions read them once
        points = ReadConditions(points, read.sent_as, read.sent_values, read.readings)
    return with_conditions(model, points or body.conditions), interval_at(model, points or body.conditions)


def _refuse_outside_law_domains(model: Model, body: OptimizationRequest) -> None:
    """422 at submit, naming the field, for a condition (or speed) whose values leave the domain of a
    calibrated model's law (:func:`calibrate.domain.outside_law_domains`): the job would fail on it."""
    if not isinstance(model, CalibratedPhysicsModel):
        return
    in_fixed = body.fixed.speed_m_s is not None
    speed = body.fixed.speed_m_s if in_fixed else body.speed_m_s
    columns = {**(body.conditions or {}), **({} if speed is None else {"speed_m_s": speed})}
    outside = outside_law_domains(model.calibrated.terms, columns)
    if outside:
        speed_pointer = "/fixed/speed_m_s" if in_fixed else "/speed_m_s"
        sent = ReadConditions.of(body.conditions)
        raise validation_problem([
            {"pointer": pointer_at("/conditions", sent.key(name)), "detail": sent.as_sent(name, detail)}
            if name != "speed_m_s" else {"pointer": speed_pointer, "detail": detail}
            for name, detail in outside.items()])


def prepare(store: Store, body: OptimizationRequest) -> OptimizationPlan:
    """Validate a request into a plan (:func:`optimize.plan.plan_design`), its model resolved.

    Parameters
    ----------
    store : Store
        Where calibrations (and surrogates) are kept.
    body : OptimizationRequest
        The request.

    Returns
    -------
    OptimizationPlan

    Raises
    ------
    ProblemError
        422 naming the field for invalid combinations, 404 for an unknown model.
    """
    request = _request(body)
    try:
        check_request(request)
    except PlanError as error:
        raise _plan_problem(error, body) from None
    model, mu_model, interval = None, None, None
    if body.model != "physics":
        model = resolve(store, body.model)
        if body.conditions:
            # The conditions as the model's columns in their units (a key as the upload's header, or in
            # another unit of a column's quantity), every value of a range judged for a unit slip: the
            # job then reads what the submit checked.
            body = body.model_copy(update={"conditions": read_conditions(model, body.conditions)})
            request = _request(body)
        _refuse_outside_law_domains(model, body)
        mu_model, interval = _bound(model, body)
    try:
        planned = plan_design(request, model)
    except PlanError as error:
        raise _plan_problem(error, body) from None
    except InfeasibleDesignError as error:
        # Conflicts of the limits that do not depend on the model answer 422 at once on every model.
        raise infeasible_problem(error) from None
    source_model, source_name = None, None
    if body.model.startswith("surrogate:"):
        source_model, source_name = load_source_model(store, body.model)
    counts = body.bounds.balls[1] - body.bounds.balls[0] + 1
    synchronous = mu_model is None and body.pareto is None and counts <= SYNC_MAX_BALL_COUNTS
    pareto = body.pareto.model_dump() if body.pareto is not None else None
    return OptimizationPlan(planned.problem, body.model, mu_model, body.starts, pareto, synchronous,
                            source_model, source_name, interval, planned.envelope, body.objective,
                            None if planned.envelope is None else model, body.time_limit_s,
                            tuple(_input_warnings(body)), ReadConditions.of(body.conditions).readings,
                            {} if body.tolerances is None else body.tolerances.readings,
                            _design_readings(body))


def _input_warnings(body: OptimizationRequest) -> list[str]:
    """The speeds and loads of a request that look like a unit slip, in the upload's words
    (:func:`physics.slips.input_slips`, as /v1/friction warns): the design is made as asked."""
    owners = {"speed_m_s": body.fixed if body.fixed.speed_m_s is not None else body,
              "load_N": body.fixed if body.fixed.load_N is not None else body.bounds}
    values = {name: getattr(owner, name) for name, owner in owners.items()}
    inputs = {name: np.atleast_1d(np.asarray(value, dtype=float)) for name, value in values.items()
              if value is not None}
    sent = {name: owner.sent_as(name) if isinstance(owner, InputKeys) else None
            for name, owner in owners.items()}
    return input_slips(inputs, sent)  # judged as each key was sent


def infeasible_problem(error: InfeasibleDesignError) -> ProblemError:
    """The 422 problem of an infeasible design problem, pointing at the conflicting fields."""
    items = []
    for name in error.conflicts:
        others = ", ".join(n for n in error.conflicts if n != name) or "the bounds"
        items.append({"pointer": _BOUND_POINTERS.get(name, f"/constraints/{name}"),
                      "detail": f"{name} conflicts with {others}"})
    items += [{"pointer": _BOUND_POINTERS[name], "detail": f"the bound {name} takes part in the conflict"}
              for name in error.binding_bounds if name in _BOUND_POINTERS]
    return ProblemError(422, str(error), title="Infeasible design problem", type_=INFEASIBLE_TYPE,
                        errors=items)


def run(plan: OptimizationPlan, progress: Callable[[float], None] | None = None,
        job_id: str | None = None, executor: Executor | None = None) -> dict[str, Any]:
    """Run a plan and return the JSON-ready result.

    Parameters
    ----------
    plan : OptimizationPlan
        From :func:`prepare`.
    progress : callable, optional
        Fraction done, 0..1. [1]
    job_id : str, optional
        The job running it, for the link to the Pareto plot.
    executor : concurrent.futures.Executor, optional
        The app's executor (:mod:`service.executor`): the groups of ball counts and starts of the
        local method run there. None runs them in this thread.

    Returns
    -------
    dict
        Fields of :class:`service.schemas.optimizations.OptimizationResult`.

    Raises
    ------
    ProblemError
        422 when the problem is infeasible.
    """
    with_pareto = plan.pareto is not None

    def stage(offset: float, share: float) -> Callable[[float], None] | None:
        if progress is None:
            return None
        return lambda fraction: progress(offset + share * fraction)

    if plan.envelope is not None:
        return _with_warnings(plan, _run_robust(plan, progress, executor))
    try:
        if plan.mu_model is None:
            result = optimize_design(plan.problem, progress=stage(0.0, 0.2 if with_pareto else 1.0))
        else:
            result = optimize_model(plan.problem, plan.mu_model, starts=plan.starts, progress=stage(0.0, 1.0),
                                    model_name=plan.model,
                                    map_calls=None if executor is None else partial(map_chunks, executor),
                                    source_model=plan.source_model, source_name=plan.source_name or "physics")
        document = {**result.to_dict(), "model": plan.model}
        if plan.interval is not None:
            # A calibrated model says how sure it is at the optimum, and whether the optimum lies in its data.
            design = {**plan.problem.fixed, **document["design"], "speed_m_s": document["speed_m_s"]}
            document.update(plan.interval(design))
        if with_pareto:
            front = pareto_front(plan.problem, plan.pareto["objective"], plan.pareto["points"],
                                 progress=stage(0.2, 0.8))
            document["pareto"] = {**front.to_dict(), "plot_url": None if job_id is None
                                  else f"/v1/optimizations/{job_id}/pareto.png"}
    except InfeasibleDesignError as error:
        raise infeasible_problem(error) from None
    return _with_warnings(plan, document)


def _with_warnings(plan: OptimizationPlan, document: dict[str, Any]) -> dict[str, Any]:
    """The result with the plan's input warnings (none: the field absent), and every design in it also
    under the bounds' keys as sent (:func:`_designs_as_sent`)."""
    document = _designs_as_sent(plan, document)
    return {**document, "input_warnings": list(plan.input_warnings)} if plan.input_warnings else document


def _designs_as_sent(plan: OptimizationPlan, document: dict[str, Any]) -> dict[str, Any]:
    """Every design of the result (the design, the Pareto front's, the price of robustness's nominal and
    robust ones) also as sent: ``design_as_sent`` beside it holds balls, groove angle and load under the
    keys the bounds (or a fixed load) were sent with, each in its key's unit (``load [gf]`` 1.2 where
    load_N is 0.01176798). Beside the design, not in it: a design stays a point that /v1/friction and
    ``physics.evaluate`` take as it is; its SI fields are unchanged."""
    sent = ReadConditions.from_readings(plan.design_readings)

    def shown(owner: Mapping[str, Any]) -> dict[str, Any]:
        design = owner["design"]
        return {**owner, "design_as_sent": sent.shown_as_sent(
            {name: design[name] for name in ("balls", "groove_angle_deg", "load_N") if name in design})}

    document = shown(document)
    if document.get("pareto"):
        document["pareto"] = {**document["pareto"],
                              "points": [shown(point) for point in document["pareto"]["points"]]}
    if document.get("price_of_robustness"):
        price = document["price_of_robustness"]
        parts = [part for part in ("nominal", "robust") if isinstance(price.get(part), Mapping)]
        document["price_of_robustness"] = {**price, **{part: shown(price[part]) for part in parts}}
    return document


def _show_as_sent(plan: OptimizationPlan, document: dict[str, Any]) -> None:
    """The envelope and its worst case (speed and conditions) also under the keys and in the units the
    request sent them in (``as_sent``), and the tolerances likewise (the envelope's ``tolerances_as_sent``:
    ``groove angle [rad]`` 0.01, not only 0.5729577951 deg)."""
    readings = {**plan.readings, **({} if plan.envelope is None else plan.envelope.readings)}
    sent = ReadConditions.from_readings(readings)
    for part in ("envelope", "worst_case"):
        shown = {"speed_m_s": document[part]["speed_m_s"], **document[part]["conditions"]}
        document[part] = {**document[part], "as_sent": sent.shown_as_sent(shown)}
    # the angle made at the worst case, under the bounds' key and in its unit (groove angle [rad])
    design = ReadConditions.from_readings(plan.design_readings)
    document["worst_case"]["as_sent"].update(
        design.shown_as_sent({"groove_angle_deg": document["worst_case"]["groove_angle_deg"]}))
    # a half-width: scaled, never offset (angles)
    widths = ReadConditions.from_readings(plan.tolerance_readings)
    document["envelope"]["tolerances_as_sent"] = widths.shown_as_sent(document["envelope"]["tolerances"])


def _run_robust(plan: OptimizationPlan, progress: Callable[[float], None] | None,
                executor: Executor | None) -> dict[str, Any]:
    """A design over the plan's envelope (:func:`optimize.robust.optimize_robust`), JSON-ready."""
    try:
        robust = optimize_robust(plan.problem, plan.envelope, plan.resolved, objective=plan.objective,
                                 starts=plan.starts, progress=progress,
                                 map_calls=None if executor is None else partial(map_chunks, executor),
                                 time_limit_s=plan.time_limit_s)
    except InfeasibleDesignError as error:
        raise infeasible_problem(error) from None
    except ValueError as exc:  # a condition outside a term's law
        raise validation_problem([{"pointer": "/conditions", "detail": str(exc)}]) from None
    document = {**robust.to_dict(), "model": plan.model}
    _show_as_sent(plan, document)
    if plan.source_model is not None:
        # A surrogate's design judged by the model it stands for, over the same envelope.
        verification = verify_over_envelope(plan.problem, plan.envelope, robust.result.design, plan.resolved,
                                            plan.model, plan.source_model, plan.source_name)
        document.update({"source_model": plan.source_name, "mu_source": verification["mu_source"],
                         "verification": verification})
    if plan.interval is not None:
        # How sure the calibrated model is, and whether its data cover it, where the worst case occurs.
        worst = robust.worst_case
        point = {**plan.problem.fixed, **document["design"], "speed_m_s": worst["speed_m_s"],
                 "groove_angle_deg": worst["groove_angle_deg"]}
        conditions = ReadConditions(worst["conditions"], readings=plan.readings)  # words in the keys sent
        document.update(interval_at(plan.resolved, conditions)(point))
    return document


def pareto_png(document: Mapping[str, Any]) -> bytes:
    """The PNG plot of the Pareto front stored in an optimization result.

    Parameters
    ----------
    document : mapping
        A result of :func:`run` with a ``pareto`` entry.

    Returns
    -------
    bytes
        PNG image.
    """
    pareto = document["pareto"]
    return ParetoFront(pareto["objective"], pareto["points"], pareto["infeasible_levels"]).to_png()

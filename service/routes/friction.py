"""``/v1/friction`` (one point) and ``/v1/friction/batch`` (columns of up to millions of points)."""

from __future__ import annotations

from concurrent.futures import Executor

from fastapi import APIRouter, Request
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from microbearing import physics

from ..calibrations import evaluate_batch_with_model, evaluate_point_with_model
from ..deps import ExecutorDep, SettingsDep, StoreDep, get_store
from ..evaluation import column_arrays, evaluate_point
from ..executor import evaluate_in_chunks
from ..models import physics_in
from ..problems import problem_responses, validation_problem
from ..schemas.base import parse_json_body, raw_json_body, with_folding_safe_names
from ..schemas.friction import FrictionBatchRequest, FrictionBatchResponse, FrictionRequest, FrictionResponse
from ..store import Store
from ..tables import json_bytes

__all__ = ["router"]

router = APIRouter(prefix="/v1/friction", tags=["friction"])


@router.post("", operation_id="evaluate_friction", response_model=FrictionResponse,
             responses=problem_responses(), openapi_extra=raw_json_body(FrictionRequest))
async def evaluate_friction(request: Request) -> Response:
    """Every output of the friction model, or of a calibrated model (``model``), at one design point."""
    # Parsed from the raw bytes, and the store looked up only for a calibrated model (no dependency
    # to resolve for a physics point): a single point is dominated by per-request overhead.
    body = await parse_json_body(request, FrictionRequest)
    # Only the inputs sent: the physics fills the same defaults (both come from its parameter table)
    # and checks each value it is given, so a field left out need not be checked again.
    sent = body.model_fields_set
    given = {name: getattr(body, name) for name in physics.PARAMETERS if name in sent}
    if body.model != "physics":
        convention = str(body.convention) if "convention" in sent else None
        document = await run_in_threadpool(evaluate_point_with_model, await get_store(request), body.model,
                                           given, body.conditions, convention)
        return Response(json_bytes(with_folding_safe_names(document)), media_type="application/json")
    _refuse_conditions(body.conditions)
    document = {"convention": str(body.convention), **evaluate_point(given, body.convention)}
    return Response(json_bytes(with_folding_safe_names(document)), media_type="application/json")


def _refuse_conditions(conditions: object) -> None:
    """422 at ``/conditions`` when a physics request gives conditions: only a calibrated model reads them."""
    if conditions is not None:
        raise validation_problem([{"pointer": "/conditions",
                                   "detail": "only a calibrated model reads conditions"}])


def _batch(request: FrictionBatchRequest, max_points: int, executor: Executor, store: Store) -> bytes:
    if request.model != "physics":
        return json_bytes(with_folding_safe_names(evaluate_batch_with_model(
            store, executor, request.model, request.points.model_dump(exclude_unset=True), request.conditions,
            request.outputs, str(request.convention) if "convention" in request.model_fields_set else None,
            max_points)))
    _refuse_conditions(request.conditions)
    inputs, count = column_arrays(request.points.model_dump(), max_points)
    # Chunks of points on the app's executor (thread pool or dask cluster, service/executor.py).
    return json_bytes(with_folding_safe_names(evaluate_in_chunks(
        executor, inputs, count, request.outputs, physics_in(request.convention), pointer="/points")))


@router.post("/batch", operation_id="evaluate_friction_batch", response_model=FrictionBatchResponse,
             response_model_exclude_none=True, responses=problem_responses(404, 413, 503),
             openapi_extra=raw_json_body(FrictionBatchRequest))
async def evaluate_friction_batch(request: Request, settings: SettingsDep, executor: ExecutorDep,
                                  store: StoreDep) -> Response:
    """The chosen outputs at many points given as columns; scalars broadcast to every point.

    With a calibrated model (``model``), its condition columns (``conditions``) and, beside ``mu``,
    ``mu_effect``, the 95 % interval ``mu_lower``/``mu_upper`` and ``in_domain`` per point, with the
    batch's ``domain_warnings``.
    """
    body = await parse_json_body(request, FrictionBatchRequest)
    content = await run_in_threadpool(_batch, body, settings.max_batch_points, executor, store)
    return Response(content, media_type="application/json")

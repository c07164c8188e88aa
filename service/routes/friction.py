"""``/v1/friction`` (one point) and ``/v1/friction/batch`` (columns of up to millions of points).

Memory of large batches: a request body over 1 MiB waits for its turn and holds a place of the
job admission control (:class:`service.limits.HeavyRequestMiddleware`). A physics batch's answer is
streamed chunk by chunk of each column (:func:`service.tables.json_column_pieces`), so it costs its
output arrays and, while they are parsed, its input lists, never its JSON: at 2e6 points with all
21 outputs the server's peak grew by about 0.5 GB, against 2.9 GB when the answer was built whole
(``bench/batch_memory.py``).
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Iterator
from concurrent.futures import Executor
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import Response, StreamingResponse
from starlette.concurrency import iterate_in_threadpool, run_in_threadpool

from microbearing import physics
from microbearing.physics.slips import input_slips

from ..calibrations import evaluate_batch_with_model, evaluate_point_with_model
from ..deps import ExecutorDep, SettingsDep, StoreDep, get_store
from ..evaluation import column_arrays, evaluate_point
from ..executor import DEFAULT_CHUNK_POINTS, evaluate_chunks
from ..models import physics_in
from ..problems import problem_responses, validation_problem
from ..schemas.base import FOLDING_SAFE_NAMES, parse_json_body, raw_json_body, with_folding_safe_names
from ..schemas.friction import FrictionBatchRequest, FrictionBatchResponse, FrictionRequest, FrictionResponse
from ..store import Store
from ..tables import json_bytes, json_column_pieces

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
                                           given, body.conditions, convention, body.readings)
    else:
        _refuse_conditions(body.conditions)
        document = {"convention": str(body.convention), **evaluate_point(given, body.convention)}
    # the upload's unit-slip rule, as a warning (the model answers as asked), judged as each key was sent
    warnings = input_slips(given, body.renamed)
    if warnings:
        document["input_warnings"] = warnings
    return Response(json_bytes(with_folding_safe_names(document)), media_type="application/json")


def _refuse_conditions(conditions: object) -> None:
    """422 at ``/conditions`` when a physics request gives conditions: only a calibrated model reads them."""
    if conditions is not None:
        raise validation_problem([{"pointer": "/conditions",
                                   "detail": "only a calibrated model reads conditions"}])


def _model_batch(request: FrictionBatchRequest, max_points: int, executor: Executor, store: Store) -> bytes:
    points = request.points.columns(sent_only=True)
    document = evaluate_batch_with_model(
        store, executor, request.model, points, request.conditions, request.outputs,
        str(request.convention) if "convention" in request.model_fields_set else None, max_points,
        request.points.readings)
    warnings = input_slips(points, request.points.renamed)
    if warnings:
        document["input_warnings"] = warnings
    return json_bytes(with_folding_safe_names(document))


def _physics_inputs(request: FrictionBatchRequest, max_points: int) -> tuple[dict[str, Any], int, list[str]]:
    """The input columns as arrays, the point count and the unit-slip warnings, judged as each key was
    sent (the parsed request can be freed then)."""
    _refuse_conditions(request.conditions)
    inputs, count = column_arrays(request.points.columns(), max_points)
    return inputs, count, input_slips(inputs, request.points.renamed)


def _physics_batch(inputs: dict[str, Any], count: int, outputs: list[str] | None, convention: str,
                   executor: Executor, warnings: list[str]) -> Iterator[bytes]:
    """Compute every chunk (errors raise here, before the answer starts); return the answer's pieces."""
    # Chunks of points on the app's executor (thread pool or dask cluster, service/executor.py).
    names, bounds, chunks = evaluate_chunks(executor, inputs, count, outputs, physics_in(convention),
                                            pointer="/points")
    inputs.clear()
    columns = [(name, name) for name in names]
    columns += [(alias, name) for name, alias in FOLDING_SAFE_NAMES.items() if name in names]
    return json_column_pieces(columns, bounds, chunks, {"input_warnings": warnings} if warnings else None)


async def _streamed(pieces: Iterator[bytes]) -> AsyncIterator[bytes]:
    """The pieces, each encoded in a worker thread."""
    async for piece in iterate_in_threadpool(pieces):
        yield piece


@router.post("/batch", operation_id="evaluate_friction_batch", response_model=FrictionBatchResponse,
             response_model_exclude_none=True, responses=problem_responses(404, 413, 429, 503),
             openapi_extra=raw_json_body(FrictionBatchRequest))
async def evaluate_friction_batch(request: Request, settings: SettingsDep, executor: ExecutorDep,
                                  store: StoreDep) -> Response:
    """The chosen outputs at many points given as columns; scalars broadcast to every point.

    With a calibrated model (``model``), its condition columns (``conditions``) and, beside ``mu``,
    ``mu_effect``, the 95 % interval ``mu_lower``/``mu_upper`` and ``in_domain`` per point, with the
    batch's ``domain_warnings``.

    A body over 1 MiB waits for one of MICROBEARING_MAX_HEAVY_REQUESTS turns (503 with Retry-After
    after MICROBEARING_HEAVY_REQUEST_WAIT_S) and counts toward the job limits while it runs (503
    past MICROBEARING_MAX_ACTIVE_JOBS, 429 past MICROBEARING_MAX_ACTIVE_JOBS_PER_KEY). An answer
    of more than 65,536 physics points is streamed (chunked transfer coding), so its memory does
    not grow with its JSON.
    """
    body = await parse_json_body(request, FrictionBatchRequest)
    if body.model != "physics":
        content = await run_in_threadpool(_model_batch, body, settings.max_batch_points, executor, store)
        return Response(content, media_type="application/json")
    inputs, count, warnings = await run_in_threadpool(_physics_inputs, body, settings.max_batch_points)
    outputs, convention = body.outputs, str(body.convention)
    del body  # the parsed lists of numbers: the arrays of the inputs are all that is needed now
    pieces = await run_in_threadpool(_physics_batch, inputs, count, outputs, convention, executor, warnings)
    del inputs
    if count <= DEFAULT_CHUNK_POINTS:  # one chunk: one piece, with its length
        return Response(b"".join(pieces), media_type="application/json")
    return StreamingResponse(_streamed(pieces), media_type="application/json")

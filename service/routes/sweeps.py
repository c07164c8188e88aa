"""``/v1/sweeps``: grids and designs of experiments; small ones answer 200, large ones run as jobs."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Request
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from ..deps import ExecutorDep, JobsDep, SettingsDep
from ..job_kinds import sweep_work
from ..problems import problem_responses
from ..schemas import examples
from ..schemas.sweeps import SweepRequest, SweepResult
from ..sweeps import check_result_size, design_columns, design_size, run_sweep, stored_request
from ..tables import CSV_MEDIA_TYPE, sweep_table, table_response
from .jobs import ACCEPTED_RESPONSE, accepted

__all__ = ["router"]

router = APIRouter(prefix="/v1/sweeps", tags=["sweeps"])

@router.post(
    "", operation_id="create_sweep", response_model=SweepResult, status_code=200,
    responses={
        200: {"description": "The sweep, computed at once: JSON, or its columns as CSV (Accept: text/csv).",
              "content": {CSV_MEDIA_TYPE: {"schema": {"type": "string"}}}},
        **ACCEPTED_RESPONSE,
        **problem_responses(503),
    },
)
async def create_sweep(
    request: Request,
    body: Annotated[SweepRequest, Body(description="A grid or a design of experiments, tagged by design.",
                                       openapi_examples=examples.media_examples(
                                           small=("A 10 x 10 grid of mu", examples.SWEEP)))],
    settings: SettingsDep,
    jobs: JobsDep,
    executor: ExecutorDep,
) -> Response:
    """Evaluate the model over a grid or a Sobol / Latin hypercube design, the other inputs fixed.

    Sweeps of up to MICROBEARING_SWEEP_SYNC_MAX_POINTS points answer 200 with the table; larger
    ones answer 202 with a job whose result is at /v1/jobs/{id}/result (the job builds the
    design when it starts). A result that could exceed MICROBEARING_MAX_RESULT_BYTES answers 413 (its size
    is bounded before any point is computed: an accepted sweep never fails for its size).
    """
    count = await run_in_threadpool(design_size, body, settings.max_sweep_points)
    await run_in_threadpool(check_result_size, body, count, settings.max_result_bytes)
    if count <= settings.sweep_sync_max_points:
        plan = await run_in_threadpool(design_columns, body, settings.max_sweep_points)
        document = await run_in_threadpool(run_sweep, body, plan, None, executor)
        return table_response(request, document, sweep_table(document))

    request = stored_request(body)  # the inputs sent under other keys as sent: the job answers in them
    return accepted(jobs.submit("sweep", request, sweep_work(body, settings, executor), inputs=request))

"""``/v1/optimizations``: minimum-friction designs (200 at once for small physics problems, else a job)."""

from __future__ import annotations

import json
from typing import Annotated, Any

from fastapi import APIRouter, Body
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from ..deps import ExecutorDep, JobsDep, StoreDep
from ..job_kinds import optimization_work
from ..optimizations import pareto_png, prepare, run
from ..problems import ProblemError, problem_responses
from ..schemas import examples
from ..schemas.optimizations import OptimizationRequest, OptimizationResult
from .jobs import NOT_FINISHED_RESPONSE, accepted, accepted_response, not_finished

__all__ = ["router"]

router = APIRouter(prefix="/v1/optimizations", tags=["optimizations"])

_KIND = "optimization"


@router.post(
    "", operation_id="create_optimization", response_model=OptimizationResult, status_code=200,
    responses={200: {"description": "The optimum, computed at once."}, **accepted_response(
        GetParetoPlot={"operationId": "get_optimization_pareto_plot",
                       "parameters": {"job_id": "$response.body#/id"},
                       "description": "The plot of the Pareto front, once the job succeeded (when it "
                                      "computes one)."}),
               **problem_responses(404)},
)
async def create_optimization(
    body: Annotated[OptimizationRequest, Body(description="Bounds, fixed inputs, speed, limits and model.",
                                              openapi_examples=examples.media_examples(
                                                  pareto=("With a Pareto front (a job)", examples.PARETO)))],
    store: StoreDep,
    jobs: JobsDep,
    executor: ExecutorDep,
) -> Any:
    """Find the design (balls, groove angle, load) of least friction within bounds and limits.

    With model physics the answer is a certified global optimum (a geometric program per ball
    count, all counts enumerated, re-checked with the exact physics). Physics problems of at most
    40 ball counts without a Pareto front answer 200; others (surrogate or calibrated models,
    Pareto fronts, wider ranges) answer 202 with a job whose result has the same fields. An
    infeasible problem answers 422 with ``errors`` pointing at the conflicting limits: at once on
    every model when the limits that do not depend on mu conflict (pressure, load per ball,
    minimum load, groove length, bounds), else as the job's problem (a friction-force limit that
    no design of a surrogate or calibrated model meets). A design found on a surrogate is verified
    by the model the surrogate stands for (see ``verification``).
    """
    plan = await run_in_threadpool(prepare, store, body)
    if plan.synchronous:
        return await run_in_threadpool(run, plan)
    request = body.model_dump(mode="json")
    return accepted(jobs.submit(_KIND, request, optimization_work(plan, executor), inputs=request))


@router.get(
    "/{job_id}/pareto.png", operation_id="get_optimization_pareto_plot",
    response_class=Response,
    responses={200: {"description": "The Pareto front as a PNG image.",
                     "content": {"image/png": {"schema": {"type": "string", "format": "binary"}}}},
               **problem_responses(404), **NOT_FINISHED_RESPONSE},
)
def get_optimization_pareto_plot(job_id: str, jobs: JobsDep) -> Response:
    """The Pareto front of an optimization job as a PNG plot."""
    row = jobs.get(job_id, with_result=True)
    if row is None or row["kind"] != _KIND:
        raise ProblemError(404, f"There is no optimization job {job_id!r}.")
    if row["status"] != "succeeded":
        raise not_finished(job_id, row["status"], "the plot")
    document = json.loads(row["result_json"])
    if not document.get("pareto"):
        raise ProblemError(404, f"Optimization job {job_id} computed no Pareto front.")
    return Response(pareto_png(document), media_type="image/png")

"""``/v1/surrogates``: train Gaussian-process surrogates of μ (a job), predict, Sobol' indices.

The work is done in :mod:`service.surrogates`; these routes parse, call and shape.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Query, Request
from fastapi.responses import JSONResponse, Response
from starlette.concurrency import run_in_threadpool

from ..deps import JobsDep, StoreDep
from ..job_kinds import surrogate_work
from ..problems import problem_responses, validation_problem
from ..schemas import examples
from ..schemas.base import parse_json_body, raw_json_body
from ..schemas.surrogates import (
    PredictRequest,
    PredictResponse,
    SensitivityResponse,
    SurrogateList,
    SurrogateRequest,
    SurrogateResult,
)
from ..surrogates import (
    KIND,
    SENSITIVITY_N,
    delete_stored,
    load_stored,
    predict,
    sensitivity,
    surrogate_view,
)
from .jobs import ACCEPTED_RESPONSE, accepted, surrogate_links
from .pages import DEFAULT_PAGE_LIMIT, PageToken, page_limit, page_of, page_start

__all__ = ["router"]

router = APIRouter(prefix="/v1/surrogates", tags=["surrogates"])


@router.post("", operation_id="create_surrogate", status_code=202,
             responses={**ACCEPTED_RESPONSE, **problem_responses(507)})
def create_surrogate(body: Annotated[SurrogateRequest, Body(openapi_examples=examples.media_examples(
        small=("mu over load and speed, 30 evaluations", examples.SURROGATE)))], store: StoreDep,
                     jobs: JobsDep) -> JSONResponse:
    """Train a surrogate of mu over a space of physics inputs (a job).

    Learns the physics, or with ``model`` a calibrated model (``conditions`` giving the extra
    columns its effect reads). Starts from a space-filling design and, with ``adaptive``, adds
    evaluations where the Gaussian process is least sure until ``target_relative_error`` or
    ``budget`` is reached; no point is evaluated twice. The job's result is the surrogate (see
    ``GET /v1/surrogates/{id}``).
    """
    work = surrogate_work(store, body)
    request = body.model_dump(mode="json")
    store.check_model_room()  # 507 now rather than a failed job later
    return accepted(jobs.submit("surrogate", request, work, inputs=request))


_SurrogatesLimit = page_limit("surrogates")


@router.get("", operation_id="list_surrogates", response_model=SurrogateList, responses={
    200: {"description": "A page of the stored surrogates the caller sees.",
          "links": surrogate_links("$response.body#/surrogates/0", "the first surrogate listed")},
    **problem_responses()})
def list_surrogates(request: Request, store: StoreDep, limit: _SurrogatesLimit = DEFAULT_PAGE_LIMIT,
                    page_token: PageToken = None) -> JSONResponse:
    """The stored surrogates the caller sees (with API keys: its key's, or all for the admin key),
    newest first.

    ``limit`` per page; ``next_url`` fetches the next page.
    """
    rows = store.list_models(KIND, limit + 1, page_start(page_token))
    page, next_url = page_of(request, rows, limit)
    return JSONResponse({"surrogates": [surrogate_view(row["id"], row["metadata"]) for row in page],
                         "next_url": next_url})



@router.get("/{surrogate_id}", operation_id="get_surrogate", response_model=SurrogateResult,
            responses={200: {"description": "The surrogate.", "links": {
                name: link for name, link in surrogate_links("$response.body#", "this surrogate").items()
                if name != "GetSurrogate"}}, **problem_responses(404)})
def get_surrogate(surrogate_id: str, store: StoreDep) -> JSONResponse:
    """A stored surrogate: its space, training summary and held-out metrics."""
    return JSONResponse(surrogate_view(surrogate_id, load_stored(store, surrogate_id).metadata))


@router.delete("/{surrogate_id}", operation_id="delete_surrogate", status_code=204,
               response_class=Response, responses=problem_responses(404))
def delete_surrogate(surrogate_id: str, store: StoreDep) -> Response:
    """Delete a stored surrogate."""
    delete_stored(store, surrogate_id)
    return Response(status_code=204)


@router.post("/{surrogate_id}/predict", operation_id="predict_surrogate", response_model=PredictResponse,
             responses=problem_responses(404), openapi_extra=raw_json_body(
                 PredictRequest, examples.media_examples(
                     loads=("Three loads at 0.05 m/s (a surrogate over load and speed)", examples.PREDICT))))
async def predict_surrogate(surrogate_id: str, request: Request, store: StoreDep) -> JSONResponse:
    """Predicted mu with its 95 % interval at columnar points, flagging points outside the space."""
    # Parsed from the raw bytes: a large body's columns are read straight into arrays (parse_json_body).
    body = await parse_json_body(request, PredictRequest)
    points = {name: value for name, value in body.points.columns().items() if value is not None}
    return JSONResponse(await run_in_threadpool(predict, store, surrogate_id, points, body.points.sent_as))


#: The base sample sizes allowed: the powers of 2 in SENSITIVITY_N (listed in the spec).
_POWERS_OF_2 = [2**k for k in range(SENSITIVITY_N[0].bit_length() - 1, SENSITIVITY_N[1].bit_length())]
assert _POWERS_OF_2[0] == SENSITIVITY_N[0] and _POWERS_OF_2[-1] == SENSITIVITY_N[1]


@router.get("/{surrogate_id}/sensitivity", operation_id="get_surrogate_sensitivity",
            response_model=SensitivityResponse, responses=problem_responses(404))
def get_surrogate_sensitivity(
    surrogate_id: str, store: StoreDep,
    n: Annotated[int, Query(ge=SENSITIVITY_N[0], le=SENSITIVITY_N[1],
                            json_schema_extra={"enum": _POWERS_OF_2},
                            description="Base sample size, a power of 2 [1].")] = 4096,
) -> JSONResponse:
    """First-order and total Sobol' indices of mu over the space, computed on the surrogate.

    Each index comes with its 95 % bootstrap confidence interval (the sampling error of the
    estimator on the surrogate, not the surrogate's own error).
    """
    if n & (n - 1):
        raise validation_problem([{"parameter": "n", "detail": f"n must be a power of 2; got {n}"}])
    return JSONResponse(sensitivity(store, surrogate_id, n))

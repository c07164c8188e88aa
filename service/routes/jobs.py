"""``/v1/jobs/{id}``: status, progress, result, cancellation and deletion of background jobs.

Finished jobs and their results are deleted ``MICROBEARING_JOB_RETENTION_S`` after they finished
(7 days by default), or at once by ``DELETE /v1/jobs/{id}``; with API keys, a job is seen only by
the key that created it (and the admin key), others get 404.
"""

from __future__ import annotations

import json
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request
from fastapi.responses import JSONResponse, Response

from ..deps import JobsDep
from ..jobs import FINISHED, POLL_AFTER_S, RETRY_AFTER_S, JobManager
from ..problems import Problem, ProblemError, problem_responses
from ..schemas.jobs import JOB_RESULTS, Job, JobKind, JobList, JobResult, JobStatus
from ..tables import CSV_MEDIA_TYPE, accepts_any, csv_text, sweep_table, wants_csv
from .pages import DEFAULT_PAGE_LIMIT, PageToken, page_limit, page_of, page_start

__all__ = ["ACCEPTED_RESPONSE", "NOT_FINISHED_RESPONSE", "accepted", "accepted_response", "calibration_links",
           "job_view", "not_finished", "router", "surrogate_links"]

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])


def job_view(row: dict[str, Any]) -> Job:
    """The public view of a job row."""
    return Job(
        id=row["id"], kind=row["kind"], status=row["status"], progress=row["progress"],
        cancel_requested=bool(row["cancel_requested"]), created_at=row["created_at"],
        started_at=row["started_at"], finished_at=row["finished_at"],
        result_url=(f"/v1/jobs/{row['id']}/result"
                    if row["status"] == "succeeded" and not row.get("erased_at") else None),
        error=Problem.model_validate(json.loads(row["error_json"])) if row["error_json"] else None,
        erased_at=row.get("erased_at"),
    )


def check_not_erased(row: dict[str, Any]) -> None:
    """A 410 problem for a job whose result was erased with the model it made or used."""
    if row.get("erased_at"):
        raise ProblemError(410, f"The result of job {row['id']} was erased at {row['erased_at']}: the "
                                "calibration or surrogate it made or used was deleted, and its data with it.",
                           title="Gone")


def accepted(row: dict[str, Any]) -> JSONResponse:
    """``202 Accepted`` with the job, ``Location: /v1/jobs/{id}`` and ``Retry-After`` (when to poll)."""
    return JSONResponse(job_view(row).model_dump(mode="json"), status_code=202,
                        headers={"Location": f"/v1/jobs/{row['id']}", "Retry-After": str(POLL_AFTER_S)})


def _job_links(pointer: str) -> dict[str, dict[str, Any]]:
    """OpenAPI links from an answer holding a job's id at ``pointer`` (a runtime expression such as
    ``$response.body#/id``) to the job's routes."""
    return {name: {"operationId": operation, "parameters": {"job_id": pointer},
                   "description": f"{what} of this job."}
            for name, operation, what in (("GetJob", "get_job", "Status"), ("GetJobResult", "get_job_result",
                                                                             "Result"),
                                          ("CancelJob", "cancel_job", "Cancellation or deletion"))}


def calibration_links(pointer: str, which: str) -> dict[str, dict[str, Any]]:
    """OpenAPI links from an answer holding a calibration at ``pointer`` (its id at ``<pointer>/id``,
    its model's id at ``<pointer>/model_id``) to the calibration's routes and the requests that
    name its model."""
    calibration, model = f"{pointer}/id", f"{pointer}/model_id"
    links = {
        name: {"operationId": operation, "parameters": {"calibration_id": calibration, **extra},
               "description": f"{what} ({which})."}
        for name, operation, extra, what in (
            ("GetCalibration", "get_calibration", {}, "The stored calibration"),
            ("GetCalibrationPlot", "get_calibration_plot", {"plot_name": "residuals"},
             "Its plot of the residuals"),
            ("CreateNextExperiments", "create_next_experiments", {}, "The next runs it asks for"),
            ("DeleteCalibration", "delete_calibration", {}, "Deletion of the calibration"))}
    # A body field taken from the answer, merged into a generated body (the rest of the body as the
    # target's schema says): the calibrated model evaluated at a point or over a batch.
    links |= {name: {"operationId": operation, "requestBody": {"model": model},
                     "description": f"{what} of the calibrated model ({which}), named in the body's model."}
              for name, operation, what in (("EvaluateCalibratedModel", "evaluate_friction", "Friction"),
                                            ("EvaluateCalibratedModelBatch", "evaluate_friction_batch",
                                             "Friction at many points"))}
    return links


def surrogate_links(pointer: str, which: str) -> dict[str, dict[str, Any]]:
    """OpenAPI links from an answer holding a surrogate at ``pointer`` (its id at ``<pointer>/id``, its
    space at ``<pointer>/space``) to the surrogate's routes.

    Predictions are asked at the ends of the space: the body's ``points`` are the space itself, each
    dimension the column of its [low, high] (``x-schemathesis.merge_body`` false: this body, not
    merged into a generated one).
    """
    links = {name: {"operationId": operation, "parameters": {"surrogate_id": f"{pointer}/id"},
                    "description": f"{what} ({which})."}
             for name, operation, what in (
                 ("GetSurrogate", "get_surrogate", "The stored surrogate"),
                 ("GetSurrogateSensitivity", "get_surrogate_sensitivity", "Its sensitivity"),
                 ("DeleteSurrogate", "delete_surrogate", "Deletion of the surrogate"))}
    links["PredictSurrogate"] = {
        "operationId": "predict_surrogate", "parameters": {"surrogate_id": f"{pointer}/id"},
        "requestBody": {"points": f"{pointer}/space"}, "x-schemathesis": {"merge_body": False},
        "description": f"Predictions of the surrogate at the two ends of its space ({which})."}
    return links


#: Links from an answer with a stored model's id at ``/id`` (a job's result) to the model's routes.
MODEL_LINKS = {**surrogate_links("$response.body#", "when the result is a surrogate's"),
               **calibration_links("$response.body#", "when the result is a calibration's")}

#: Links from a job's result to the plot of that result (an optimization's Pareto front, a proposal's runs).
RESULT_PLOT_LINKS = {
    name: {"operationId": operation, "parameters": {"job_id": "$request.path.job_id"},
           "description": f"{what} (when the result is {which})."}
    for name, operation, what, which in (
        ("GetParetoPlot", "get_optimization_pareto_plot", "The plot of its Pareto front",
         "an optimization's with a Pareto front"),
        ("GetExperimentsPlot", "get_experiments_plot", "The plot of the proposed runs", "a proposal's"))}

_RETRY_AFTER_HEADER = {"description": "Seconds to wait before trying again.", "schema": {"type": "integer"}}


def accepted_response(**links: dict[str, Any]) -> dict[int | str, dict[str, Any]]:
    """OpenAPI entries of a 202 answer (its links to the job's routes, and ``links`` to the routes
    of this kind of job) and of the refusals of a full queue, for a route that may run its work as a job."""
    return {
        202: {"model": Job, "description": "Accepted: the work runs as a job; poll the Location header.",
              "links": {**_job_links("$response.body#/id"), **links},
              "headers": {"Location": {"description": "Path of the job, /v1/jobs/{id}.",
                                       "schema": {"type": "string"}},
                          "Retry-After": {"description": "Seconds to wait before polling the job.",
                                          "schema": {"type": "integer"}}}},
        429: {"model": Problem,
              "description": f"Too many queued or running jobs of this API key; retry after Retry-After "
                             f"(about {RETRY_AFTER_S} s).",
              "headers": {"Retry-After": _RETRY_AFTER_HEADER}},
        503: {"model": Problem,
              "description": "The server holds its limit of queued or running jobs, or cannot store data; "
                             "retry after Retry-After.",
              "headers": {"Retry-After": _RETRY_AFTER_HEADER}},
    }


#: :func:`accepted_response` without links of a kind.
ACCEPTED_RESPONSE = accepted_response()

#: The 409 of a route that needs a succeeded job, with when to ask again and links back to the job.
NOT_FINISHED_RESPONSE: dict[int | str, dict[str, Any]] = {409: {
    "model": Problem,
    "description": "The job has not succeeded: queued or running (ask again after Retry-After, or poll the "
                   "job), or failed or cancelled (the problem says which).",
    "headers": {"Retry-After": {"description": "While the job is queued or running: seconds to wait before "
                                               "asking again.", "schema": {"type": "integer"}}},
    "links": _job_links("$request.path.job_id")}}


def not_finished(job_id: str, status: str, what: str) -> ProblemError:
    """409 for a job that has not succeeded: ``what`` exists once it has; Retry-After while it may."""
    return ProblemError(409, f"Job {job_id} is {status}; {what} exists only once it succeeded.",
                        headers={"Retry-After": str(POLL_AFTER_S)} if status not in FINISHED else None)


def _job_or_404(jobs: JobManager, job_id: str, with_result: bool = False) -> dict[str, Any]:
    row = jobs.get(job_id, with_result=with_result)
    if row is None:
        raise ProblemError(404, f"There is no job {job_id!r}.")
    return row


_JobsLimit = page_limit("jobs")
assert set(JobKind.__args__) == set(JOB_RESULTS)  # a new kind of job is listed too


@router.get("", operation_id="list_jobs", response_model=JobList, responses=problem_responses())
def list_jobs(
    request: Request, jobs: JobsDep,
    kind: Annotated[list[JobKind], Query(description="Only jobs of these kinds (repeatable).")] = [],  # noqa: B006
    status: Annotated[list[JobStatus], Query(
        description="Only jobs with these statuses (repeatable).")] = [],  # noqa: B006
    limit: _JobsLimit = DEFAULT_PAGE_LIMIT,
    page_token: PageToken = None,
) -> JobList:
    """The caller's jobs (with API keys: those its key created; the admin key: all), newest first.

    Filtered by ``kind`` and ``status``, ``limit`` per page; ``next_url`` fetches the next page.
    Finished jobs are deleted MICROBEARING_JOB_RETENTION_S after they finished.
    """
    rows = jobs.list(tuple(kind), tuple(status), limit + 1, page_start(page_token))
    filters = [("kind", k) for k in kind] + [("status", s) for s in status]
    page, next_url = page_of(request, rows, limit, filters)
    return JobList(jobs=[job_view(row) for row in page], next_url=next_url)


@router.get("/{job_id}", operation_id="get_job", response_model=Job,
            responses={200: {"description": "The job.", "links": _job_links("$response.body#/id")},
                       **problem_responses(404)})
def get_job(job_id: str, jobs: JobsDep) -> Job:
    """Status, progress and, once finished, the result link or the problem of a job."""
    return job_view(_job_or_404(jobs, job_id))


@router.delete("/{job_id}", operation_id="cancel_job", response_model=Job,
               responses={204: {"description": "The finished job and its result were deleted."},
                          **problem_responses(404, 409)})
def cancel_job(job_id: str, jobs: JobsDep) -> Any:
    """Cancel a queued or running job (200 with the job), or delete a finished one (204).

    A queued job ends at once, a running one at its next progress check. A running job whose
    work returns after this request still ends cancelled (its result is discarded): an answer
    with ``cancel_requested`` true always ends in ``cancelled`` (or ``failed`` should the work
    fail). A finished job (succeeded, failed or cancelled) is deleted with its result; the
    job's id then answers 404. Finished jobs are also deleted MICROBEARING_JOB_RETENTION_S after
    they finished.
    """
    row = _job_or_404(jobs, job_id)
    if row["status"] in FINISHED:
        if not jobs.delete(job_id):
            _job_or_404(jobs, job_id)  # deleted by another request meanwhile: 404
            raise ProblemError(409, f"Job {job_id} cannot be deleted yet: its final state is not stored "
                                    "(the data folder refuses writes).")
        return Response(status_code=204)
    row = jobs.cancel(job_id)
    if row is None:  # finished and deleted by a concurrent request since it was read
        raise ProblemError(404, f"There is no job {job_id!r}.")
    return job_view(row)


@router.get(
    "/{job_id}/result", operation_id="get_job_result",
    responses={
        200: {"model": JobResult,
              "description": "The result, tagged with the job's kind: JSON, or its columns as CSV with "
                             "Accept: text/csv (sweeps).",
              "links": {**MODEL_LINKS, **RESULT_PLOT_LINKS},
              "content": {CSV_MEDIA_TYPE: {"schema": {"type": "string"}}}},
        **problem_responses(404, 406, 410), **NOT_FINISHED_RESPONSE,
    },
)
def get_job_result(job_id: str, request: Request, jobs: JobsDep) -> Response:
    """The result of a succeeded job, as stored."""
    row = _job_or_404(jobs, job_id, with_result=True)
    if row["status"] != "succeeded":
        raise not_finished(job_id, row["status"], "a result")
    check_not_erased(row)
    if wants_csv(request):
        result = json.loads(row["result_json"])
        if isinstance(result.get("columns"), dict):
            return Response(csv_text(sweep_table(result)), media_type=CSV_MEDIA_TYPE)
        # not a table: JSON, where the header admits it at all (a lower quality is still acceptable)
        if not accepts_any(request.headers.get("accept", ""), ["application/json"]):
            raise ProblemError(406, f"The result of job {job_id} is not a table; ask for application/json.")
    return Response(_tagged(row["kind"], row["result_json"]), media_type="application/json")


def _tagged(kind: str, result_json: str) -> bytes:
    """The stored JSON object of a result with ``"kind"`` first, without parsing it (a sweep may be large).

    >>> _tagged("sweep", '{"count": 0}'), _tagged("sweep", '{}')
    (b'{"kind":"sweep","count": 0}', b'{"kind":"sweep"}')
    """
    body = result_json.strip()[1:].lstrip()
    head = '{"kind":' + json.dumps(kind)
    return (head + ("}" if body == "}" else "," + body)).encode()

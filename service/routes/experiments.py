"""Which measurements to take next: ``POST /v1/calibrations/{id}/next-experiments``, ``POST /v1/experiments``
(jobs), and the plot of a proposal."""

from __future__ import annotations

import json
from typing import Annotated

from fastapi import APIRouter, Body
from fastapi.responses import JSONResponse, Response

from ..deps import JobsDep, StoreDep
from ..experiments import JOB_KIND, first_experiments_job, next_experiments_job, plan_png
from ..problems import ProblemError, problem_responses
from ..schemas import examples
from ..schemas.experiments import FirstExperimentsRequest, NextExperimentsRequest
from .jobs import NOT_FINISHED_RESPONSE, accepted, accepted_response, check_not_erased, not_finished

__all__ = ["router"]

router = APIRouter(tags=["experiments"])


#: A proposal's 202, with a link to its plot.
_ACCEPTED = accepted_response(GetExperimentsPlot={
    "operationId": "get_experiments_plot", "parameters": {"job_id": "$response.body#/id"},
    "description": "The plot of the proposed runs, once the job succeeded."})


@router.post("/v1/calibrations/{calibration_id}/next-experiments", operation_id="create_next_experiments",
             status_code=202, responses={**_ACCEPTED, **problem_responses(404)})
def create_next_experiments(calibration_id: str, body: Annotated[NextExperimentsRequest, Body(
        openapi_examples=examples.media_examples(
            six=("Six runs over 4-12 balls, 3-24 mN and two speeds", examples.NEXT_EXPERIMENTS)))],
                            store: StoreDep,
                            jobs: JobsDep) -> JSONResponse:
    """Propose the next runs for a calibration, with an optimality bound (a job).

    The job's result (``ExperimentsJobResult``) lists the runs (integer ball counts, inside the space,
    replicates allowed), the criterion, ``efficiency_lower_bound`` (how far the runs can be from the
    best design over the candidate points, rounding included) and what the runs are expected to do:
    the parameters' standard deviations now and after, the 95 % interval over the envelope now and
    after, the rivals and how far apart the runs set them (``discriminate``); the plot at
    ``plot_url``. A space, fixed value or planned run the calibration cannot read is a 422 naming it.
    """
    work = next_experiments_job(store, calibration_id, body)
    request = {"calibration_id": calibration_id, **body.model_dump(mode="json")}
    return accepted(jobs.submit(JOB_KIND, request, work, inputs=request))


@router.post("/v1/experiments", operation_id="create_first_experiments", status_code=202,
             responses={**_ACCEPTED, **problem_responses()})
def create_first_experiments(body: Annotated[FirstExperimentsRequest, Body(
        openapi_examples=examples.media_examples(
            six=("Six first runs to fit mu_pivot", examples.FIRST_EXPERIMENTS)))],
                             jobs: JobsDep) -> JSONResponse:
    """Propose a first set of runs on the declared physics, before any calibration (a job).

    The same operation as ``/v1/calibrations/{id}/next-experiments`` with the declared parameters to fit
    (``fit_parameters``) at their defaults or ``guess`` and an expected relative scatter
    (``noise_std_log``); goals ``parameters`` and ``predict``.
    """
    request = body.model_dump(mode="json")
    return accepted(jobs.submit(JOB_KIND, request, first_experiments_job(body), inputs=request))


@router.get("/v1/experiments/{job_id}/plot.png", operation_id="get_experiments_plot", response_class=Response,
            responses={200: {"description": "The proposed runs over the data taken (and the rivals' "
                                            "predictions for discriminate) as a PNG image.",
                             "content": {"image/png": {"schema": {"type": "string", "format": "binary"}}}},
                       **problem_responses(404, 410), **NOT_FINISHED_RESPONSE})
def get_experiments_plot(job_id: str, jobs: JobsDep) -> Response:
    """The plot of a proposal: the runs over the data taken, with the rivals' predictions."""
    row = jobs.get(job_id, with_result=True)
    if row is None or row["kind"] != JOB_KIND:
        raise ProblemError(404, f"There is no experiments job {job_id!r}.")
    if row["status"] != "succeeded":
        raise not_finished(job_id, row["status"], "the plot")
    check_not_erased(row)
    return Response(plan_png(json.loads(row["result_json"])), media_type="image/png")

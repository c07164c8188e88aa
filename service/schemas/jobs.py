"""The job resource."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from ..problems import Problem
from .base import NEXT_URL, DateTimeText, ResponseModel
from .calibrations import CalibrationResult
from .experiments import ExperimentsResult
from .optimizations import OptimizationResult
from .surrogates import SurrogateResult
from .sweeps import SweepResult

__all__ = ["JOB_RESULTS", "Job", "JobKind", "JobList", "JobResult", "JobStatus"]

JobStatus = Literal["queued", "running", "succeeded", "failed", "cancelled"]
JobKind = Literal["sweep", "optimization", "calibration", "surrogate", "experiments"]


class Job(ResponseModel):
    """A background job: long work answered with 202 and polled at ``/v1/jobs/{id}``."""

    id: str = Field(description="Identifier of the job.")
    kind: str = Field(description="What the job does, e.g. sweep.")
    status: JobStatus = Field(description="queued, running, succeeded, failed or cancelled.")
    progress: float = Field(ge=0, le=1, description="Share of the work done [1].")
    cancel_requested: bool = Field(description="Whether DELETE /v1/jobs/{id} asked the job to stop.")
    created_at: DateTimeText = Field(description="When the job was submitted (ISO 8601, UTC).")
    started_at: DateTimeText | None = Field(default=None,
                                            description="When it started running (ISO 8601, UTC).")
    finished_at: DateTimeText | None = Field(default=None, description="When it ended (ISO 8601, UTC).")
    result_url: str | None = Field(
        default=None, description="Path of the result once succeeded (JSON, or CSV with Accept: text/csv).")
    error: Problem | None = Field(default=None, description="Why the job failed, as a problem.")
    erased_at: DateTimeText | None = Field(
        default=None, description="When its request, inputs and result were erased, because a calibration or "
                                  "surrogate it made or used was deleted (ISO 8601, UTC); its result then "
                                  "answers 410.")


class SweepJobResult(SweepResult):
    """The result of a sweep job: the table of ``POST /v1/sweeps``, tagged with the job kind."""

    kind: Literal["sweep"] = Field(description="Kind of the job that made the result: sweep.")


class OptimizationJobResult(OptimizationResult):
    """The result of an optimization job: as ``POST /v1/optimizations`` answers at once."""

    kind: Literal["optimization"] = Field(description="Kind of the job that made the result: optimization.")


class CalibrationJobResult(CalibrationResult):
    """The result of a calibration job: the report of ``GET /v1/calibrations/{id}``."""

    kind: Literal["calibration"] = Field(description="Kind of the job that made the result: calibration.")


class SurrogateJobResult(SurrogateResult):
    """The result of a surrogate job: the surrogate of ``GET /v1/surrogates/{id}``."""

    kind: Literal["surrogate"] = Field(description="Kind of the job that made the result: surrogate.")


class ExperimentsJobResult(ExperimentsResult):
    """The result of a job proposing runs (``/v1/calibrations/{id}/next-experiments`` or
    ``/v1/experiments``)."""

    kind: Literal["experiments"] = Field(description="Kind of the job that made the result: experiments.")


#: Result model of every job kind (the kind given to ``JobManager.submit``); add a kind here.
JOB_RESULTS = {"sweep": SweepJobResult, "optimization": OptimizationJobResult,
               "calibration": CalibrationJobResult, "surrogate": SurrogateJobResult,
               "experiments": ExperimentsJobResult}

#: The JSON result of ``GET /v1/jobs/{id}/result``, told apart by ``kind`` (the job's kind).
JobResult = Annotated[SweepJobResult | OptimizationJobResult | CalibrationJobResult | SurrogateJobResult
                      | ExperimentsJobResult, Field(discriminator="kind")]


class JobList(ResponseModel):
    """A page of the caller's jobs, newest first."""

    jobs: list[Job] = Field(description="The jobs of this page (at most limit).")
    next_url: str | None = NEXT_URL

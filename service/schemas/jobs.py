"""The job resource."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from ..problems import Problem
from .base import ResponseModel

__all__ = ["Job", "JobStatus"]

JobStatus = Literal["queued", "running", "succeeded", "failed", "cancelled"]


class Job(ResponseModel):
    """A background job: long work answered with 202 and polled at ``/v1/jobs/{id}``."""

    id: str = Field(description="Identifier of the job.")
    kind: str = Field(description="What the job does, e.g. sweep.")
    status: JobStatus = Field(description="queued, running, succeeded, failed or cancelled.")
    progress: float = Field(ge=0, le=1, description="Share of the work done [1].")
    cancel_requested: bool = Field(description="Whether DELETE /v1/jobs/{id} asked the job to stop.")
    created_at: str = Field(description="When the job was submitted (ISO 8601, UTC).")
    started_at: str | None = Field(default=None, description="When it started running (ISO 8601, UTC).")
    finished_at: str | None = Field(default=None, description="When it ended (ISO 8601, UTC).")
    result_url: str | None = Field(
        default=None, description="Path of the result once succeeded (JSON, or CSV with Accept: text/csv).")
    error: Problem | None = Field(default=None, description="Why the job failed, as a problem.")

"""The service's job kinds in one table, and the work of each.

A route that runs work as a job submits it with its inputs (:meth:`service.jobs.JobManager.submit`,
``inputs=``); the kind's :class:`~service.jobs.JobKind` in :data:`JOB_KIND_TABLE` rebuilds the same
work from those stored inputs in any server process sharing the data folder, so the job survives
restarts and can run anywhere. The routes build their work with the functions below, so a job run at
once and one rebuilt later do the same. :func:`register_job_kinds`, called by
:func:`service.app.create_app`, declares the table to :mod:`service.jobs`: importing a route registers
nothing. A new kind is one entry here (README, "Jobs across restarts and processes", states each rule).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from concurrent.futures import Executor
from typing import Any

from pydantic import TypeAdapter

from microbearing.calibrate import Dataset

from .calibrations import run_calibration
from .experiments import JOB_KIND as EXPERIMENTS_KIND
from .experiments import first_experiments_job, next_experiments_job
from .jobs import JobContext, JobKind, register_kind
from .optimizations import OptimizationPlan, prepare, run
from .schemas.experiments import FirstExperimentsRequest, NextExperimentsRequest
from .schemas.optimizations import OptimizationRequest
from .schemas.surrogates import SurrogateRequest
from .schemas.sweeps import GridSweep, LatinHypercubeSweep, SobolSweep, SweepRequest
from .settings import Settings
from .store import Store, json_bytes
from .surrogates import prepare_training, train_surrogate
from .sweeps import design_columns, run_sweep

__all__ = ["JOB_KIND_TABLE", "Work", "calibration_inputs", "calibration_work", "optimization_work",
           "register_job_kinds", "surrogate_work", "sweep_work"]

#: What a job runs: ``work(ctx) -> result`` (JSON-ready; see :mod:`service.jobs`).
Work = Callable[[JobContext], dict[str, Any]]

_SWEEP_REQUEST: TypeAdapter[GridSweep | SobolSweep | LatinHypercubeSweep] = TypeAdapter(SweepRequest)


def sweep_work(body: GridSweep | SobolSweep | LatinHypercubeSweep, settings: Settings,
               executor: Executor | None) -> Work:
    """A sweep's work: its points are built when the job starts (a queued job holds only its request)."""
    def work(ctx: JobContext) -> dict[str, Any]:
        plan = design_columns(body, settings.max_sweep_points)
        return run_sweep(body, plan, progress=ctx.progress, executor=executor)

    return work


def optimization_work(plan: OptimizationPlan, executor: Executor | None) -> Work:
    """An optimization's work: its plan run (:func:`service.optimizations.run`)."""
    def work(ctx: JobContext) -> dict[str, Any]:
        return run(plan, progress=ctx.progress, job_id=ctx.job_id, executor=executor)

    return work


def surrogate_work(store: Store, body: SurrogateRequest) -> Work:
    """A surrogate's training; its space and the model it learns are checked now (422 or 404 here)."""
    space, mu_model = prepare_training(store, body)

    def work(ctx: JobContext) -> dict[str, Any]:
        return train_surrogate(store, space, body, progress=ctx.progress, mu_model=mu_model)

    return work


def calibration_work(store: Store, dataset: Dataset, fit_parameters: list[str], folds: int, convention: str,
                     intake: dict[str, Any]) -> Work:
    """A calibration's work on checked measurements (:func:`service.calibrations.run_calibration`)."""
    def work(ctx: JobContext) -> dict[str, Any]:
        return run_calibration(store, dataset, fit_parameters, folds, convention, progress=ctx.progress,
                               intake=intake)

    return work


def calibration_inputs(dataset: Dataset, fit_parameters: list[str], folds: int, convention: str,
                       intake: dict[str, Any]) -> dict[str, Any]:
    """What a calibration job stores to be rebuilt: its checked measurements (:meth:`Dataset.to_columns`,
    bounded by the row and column limits) and the request's choices."""
    return {"data": {name: values.tolist() for name, values in dataset.to_columns().items()},
            "fixed": dataset.fixed, "fit_parameters": fit_parameters, "folds": folds,
            "convention": convention, "intake": intake}


def _sweep(inputs: dict[str, Any], runtime: Any) -> Work:
    return sweep_work(_SWEEP_REQUEST.validate_json(json_bytes(inputs)), runtime.settings, runtime.executor)


def _optimization(inputs: dict[str, Any], runtime: Any) -> Work:
    plan = prepare(runtime.store, OptimizationRequest.model_validate_json(json.dumps(inputs)))
    return optimization_work(plan, runtime.executor)


def _surrogate(inputs: dict[str, Any], runtime: Any) -> Work:
    return surrogate_work(runtime.store, SurrogateRequest.model_validate_json(json_bytes(inputs)))


def _calibration(inputs: dict[str, Any], runtime: Any) -> Work:
    dataset = Dataset.from_columns(inputs["data"], inputs["fixed"])
    return calibration_work(runtime.store, dataset, inputs["fit_parameters"], inputs["folds"],
                            inputs["convention"], inputs.get("intake") or {})


def _experiments(inputs: dict[str, Any], runtime: Any) -> Work:
    """A proposal from its stored request (and calibration id, for the next runs)."""
    request = dict(inputs)
    calibration_id = request.pop("calibration_id", None)
    if calibration_id is None:
        return first_experiments_job(FirstExperimentsRequest.model_validate_json(json.dumps(request)))
    return next_experiments_job(runtime.store, calibration_id,
                                NextExperimentsRequest.model_validate_json(json.dumps(request)))


#: Every kind of job the service runs, with how a process rebuilds its work from the stored inputs
#: (``build(inputs, runtime)``) and what an interrupted run does (``requeue``, ``rule``).
JOB_KIND_TABLE: tuple[JobKind, ...] = (
    # Deterministic, it stores nothing but its result.
    JobKind("sweep", _sweep,
            rule="deterministic; the request is stored and the result is written once, at the end"),
    # Rebuilt from the request; a model deleted meanwhile fails the new run with 404.
    JobKind("optimization", _optimization,
            rule="the request is stored and the result is written once, at the end"),
    JobKind("surrogate", _surrogate,
            rule="the model is stored in one transaction at the end: an interrupted run leaves nothing"),
    # The parsed data are stored with the job; the calibration is stored in one transaction at the end.
    JobKind("calibration", _calibration,
            rule="its checked data are stored with it; the calibration is stored in one transaction at the "
                 "end: an interrupted run leaves nothing"),
    # Rebuilt from the request; a calibration deleted meanwhile fails the new run with 404.
    JobKind(EXPERIMENTS_KIND, _experiments,
            rule="the request is stored and the result is written once, at the end"),
)


def register_job_kinds() -> None:
    """Declare every kind of :data:`JOB_KIND_TABLE` to :mod:`service.jobs` (again: the same kinds)."""
    for kind in JOB_KIND_TABLE:
        register_kind(kind.name, kind.build, requeue=kind.requeue, rule=kind.rule)

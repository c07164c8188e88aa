"""``/healthz``, ``/readyz``, ``/v1/version``, ``/v1/materials`` and ``/v1/parameters``."""

from __future__ import annotations

import shutil
from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter

from microbearing import physics
from microbearing.calibrate.tabular import accepted_names

from ..deps import ExecutorDep, JobsDep, SettingsDep, StoreDep
from ..problems import ProblemError, problem_responses
from ..schemas.meta import (
    Health,
    MaterialInfo,
    Materials,
    OutputInfo,
    ParameterInfo,
    Parameters,
    Readiness,
    Version,
)

__all__ = ["package_version", "router"]

router = APIRouter(tags=["meta"])


def package_version() -> str:
    """The installed version of the microbearing package."""
    try:
        return version("microbearing")
    except PackageNotFoundError:
        return "0+unknown"


@router.get("/healthz", operation_id="get_health", response_model=Health, responses=problem_responses())
async def get_health() -> Health:
    """Liveness: answers ok whenever the server runs."""
    return Health(status="ok")


@router.get("/readyz", operation_id="get_readiness", response_model=Readiness,
            responses=problem_responses(503))
def get_readiness(store: StoreDep, jobs: JobsDep, settings: SettingsDep, executor: ExecutorDep) -> Readiness:
    """Readiness: 200 when the database takes a write and the disk has MICROBEARING_MIN_FREE_BYTES free.

    With MICROBEARING_DASK_SCHEDULER set to a scheduler's address, the scheduler must also be
    reachable (connecting again if the connection was lost) and have a worker that answers (a worker
    whose heartbeat stopped, e.g. a stopped process or a hung host, is named).

    503 otherwise, naming the cause (disk full, read-only database, too little free space, the
    dask scheduler unreachable or without workers); take the server out of a load balancer's
    rotation then. Liveness is ``/healthz``.
    """
    reason = store.check_writable(settings.min_free_bytes)
    fault = getattr(executor, "fault", None)
    if reason is None and fault is not None and (cluster := fault()) is not None:
        reason = f"the dask scheduler {settings.dask_scheduler} {cluster.rstrip('.')}"
    if reason is not None:
        raise ProblemError(503, f"Not ready: {reason}.", title="Not ready", headers={"Retry-After": "30"})
    return Readiness(status="ready", free_bytes=shutil.disk_usage(store.data_dir).free,
                     active_jobs=jobs.active_count())


@router.get("/v1/version", operation_id="get_version", response_model=Version, responses=problem_responses())
async def get_version() -> Version:
    """Package version and the physics convention used by default."""
    return Version(name="microbearing", version=package_version(),
                   physics_convention=physics.DEFAULT_CONVENTION, conventions=dict(physics.CONVENTIONS))


@router.get("/v1/materials", operation_id="list_materials", response_model=Materials,
            responses=problem_responses())
async def list_materials() -> Materials:
    """Published elastic properties of ball and race materials (see physics.material_parameters)."""
    return Materials(materials=[
        MaterialInfo(name=m.name, youngs_modulus_Pa=m.youngs_modulus_Pa, poisson_ratio=m.poisson_ratio,
                     density_kg_m3=m.density_kg_m3, source=m.source)
        for m in physics.MATERIALS.values()
    ])


@router.get("/v1/parameters", operation_id="list_parameters", response_model=Parameters,
            responses=problem_responses())
async def list_parameters() -> Parameters:
    """Every physics input with its unit, default and allowed range, every output with its unit, and
    the column names measured data may use (units in the header are converted to SI)."""
    return Parameters(
        parameters=[ParameterInfo(name=p.name, unit=p.unit, kind=p.kind, required=p.required,
                                  default=p.default, minimum=p.minimum, maximum=p.maximum,
                                  exclusive_minimum=p.exclusive_minimum,
                                  exclusive_maximum=p.exclusive_maximum, symbol=p.symbol,
                                  description=p.description)
                    for p in physics.PARAMETERS.values()],
        outputs=[OutputInfo(name=name, unit=unit, description=text)
                 for name, (unit, text) in physics.OUTPUTS.items()],
        data_columns=accepted_names())

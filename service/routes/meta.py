"""``/healthz``, ``/v1/version`` and ``/v1/materials``."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter

import physics

from ..problems import problem_responses
from ..schemas.meta import Health, MaterialInfo, Materials, Version

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

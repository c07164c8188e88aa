"""Health, version and materials."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import ConventionName, ResponseModel

__all__ = ["Health", "MaterialInfo", "Materials", "Version"]


class Health(ResponseModel):
    """Liveness of the server."""

    status: Literal["ok"] = Field(description="Always ok when the server answers.")


class Readiness(ResponseModel):
    """Readiness of the server: its database takes writes and its disk has room."""

    status: Literal["ready"] = Field(description="ready when the server can accept work.")
    free_bytes: int = Field(description="Free space of the data folder's file system [bytes].")
    active_jobs: int = Field(description="Queued and running jobs of the data folder, every server process "
                                         "sharing it [1].")


class Version(ResponseModel):
    """What is running."""

    name: str = Field(description="Package name.")
    version: str = Field(description="Package version.")
    physics_convention: ConventionName = Field(description="Default reading of the paper's ball-ball terms.")
    conventions: dict[str, str] = Field(description="Every available convention and what it means.")


class MaterialInfo(ResponseModel):
    """Elastic properties of one ball or race material."""

    name: str = Field(description="Key to use in requests.")
    youngs_modulus_Pa: float = Field(description="Young's modulus [Pa].")
    poisson_ratio: float = Field(description="Poisson's ratio [1].")
    density_kg_m3: float = Field(description="Density [kg/m^3].")
    source: str = Field(description="Where the values come from.")


class Materials(ResponseModel):
    """The material table."""

    materials: list[MaterialInfo] = Field(description="Every known material.")

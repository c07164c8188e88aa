"""Health, version, materials and the parameter table."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import ConventionName, ResponseModel

__all__ = ["Health", "MaterialInfo", "Materials", "OutputInfo", "ParameterInfo", "Parameters", "Version"]


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


class ParameterInfo(ResponseModel):
    """One physics input: a field of every request and a column of measured data."""

    name: str = Field(description="Field and column name, with its unit (load_N [N]).")
    unit: str = Field(description="Its SI unit ('1': dimensionless; deg for the groove angle).")
    kind: Literal["float", "int", "bool"] = Field(description="Value type.")
    required: bool = Field(description="True for design and operating inputs without a default.")
    default: float | bool | None = Field(description="Default value [unit]; null when required.")
    minimum: float | None = Field(description="Lower bound of the allowed range [unit].")
    maximum: float | None = Field(description="Upper bound of the allowed range [unit].")
    exclusive_minimum: bool = Field(description="Whether the lower bound itself is excluded.")
    exclusive_maximum: bool = Field(description="Whether the upper bound itself is excluded.")
    symbol: str = Field(description="Symbol in Olaru et al. (2005).")
    description: str = Field(description="What it means.")


class OutputInfo(ResponseModel):
    """One output of the friction model."""

    name: str = Field(description="Output name, with its unit.")
    unit: str = Field(description="Its SI unit ('1': dimensionless).")
    description: str = Field(description="What it means.")


class Parameters(ResponseModel):
    """Every input and output of the physics, and how measured data may name its columns."""

    parameters: list[ParameterInfo] = Field(description="Every physics input, in the order of the physics.")
    outputs: list[OutputInfo] = Field(description="Every physics output.")
    data_columns: str = Field(description="Column names of measured data (calibrations), with the units "
                                          "converted to SI.")

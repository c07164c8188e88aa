"""Service settings, read from the environment with the prefix ``MICROBEARING_``.

Every field can be set as ``MICROBEARING_<FIELD NAME IN CAPITALS>``, e.g.
``MICROBEARING_DATA_DIR=/srv/microbearing`` or ``MICROBEARING_MAX_BATCH_POINTS=5000000``.
The README's settings table lists them; :func:`settings_table` builds it from this class.
"""

from __future__ import annotations

from pathlib import Path

import platformdirs
from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["ENV_PREFIX", "Settings", "default_data_dir", "settings_table"]

ENV_PREFIX = "MICROBEARING_"


def default_data_dir() -> Path:
    """The per-user data folder of the service (``platformdirs.user_data_dir("microbearing")``)."""
    return Path(platformdirs.user_data_dir("microbearing"))


class Settings(BaseSettings):
    """Configuration of one service instance; immutable once the app is built."""

    model_config = SettingsConfigDict(env_prefix=ENV_PREFIX, frozen=True, extra="forbid")

    data_dir: Path = Field(
        default_factory=default_data_dir,
        description="Folder holding the SQLite database of jobs and stored models.",
    )
    max_body_bytes: int = Field(
        default=256 * 2**20, ge=1024,
        description="Largest accepted request body [bytes]; larger bodies get 413.",
    )
    max_batch_points: int = Field(
        default=2_000_000, ge=1,
        description="Most points in one /v1/friction/batch request; more get 413.",
    )
    max_sweep_points: int = Field(
        default=2_000_000, ge=1,
        description="Most points in one sweep; larger designs get 422.",
    )
    sweep_sync_max_points: int = Field(
        default=10_000, ge=0,
        description="Sweeps of at most this many points answer 200 at once; larger ones run as jobs (202).",
    )
    job_workers: int = Field(
        default=2, ge=1, le=64,
        description="Background threads running jobs in each server process.",
    )
    # Reliability and scale-out (service/security.py, service/executor.py).
    api_keys: SecretStr = Field(
        default=SecretStr(""),
        description="Comma-separated API keys; when set, every request except /healthz, /metrics and the "
                    "API docs needs `Authorization: Bearer <key>` (401 otherwise). Empty: no keys needed.",
    )
    dask_scheduler: str | None = Field(
        default=None,
        description="Run sweep and batch chunks and the groups of multi-start optimizations on "
                    "dask.distributed: a scheduler address (tcp://host:8786) or `local` for an embedded "
                    "LocalCluster. Unset: a local thread pool.",
    )
    executor_workers: int = Field(
        default=0, ge=0, le=256,
        description="Threads running sweep and batch chunks and optimization groups (local pool or "
                    "embedded cluster); 0: one per CPU.",
    )


def settings_table() -> str:
    """The settings as a Markdown table (variable, default, meaning) for the README."""
    rows = ["| Environment variable | Default | Meaning |", "|---|---|---|"]
    for name, field in Settings.model_fields.items():
        if field.default_factory is not None:
            default = "user data dir / microbearing"
        else:
            value = field.default
            plain = value.get_secret_value() if isinstance(value, SecretStr) else value
            default = "unset" if plain is None else "empty" if plain == "" else plain
        rows.append(f"| `{ENV_PREFIX}{name.upper()}` | {default} | {field.description} |")
    return "\n".join(rows)

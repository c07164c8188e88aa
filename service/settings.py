"""Service settings, read from the environment with the prefix ``MICROBEARING_``.

Every field can be set as ``MICROBEARING_<FIELD NAME IN CAPITALS>``, e.g.
``MICROBEARING_DATA_DIR=/srv/microbearing`` or ``MICROBEARING_MAX_BATCH_POINTS=5000000``.
The README's settings table lists them; :func:`settings_table` builds it from this class.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import platformdirs
from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from microbearing import physics

__all__ = ["ENV_PREFIX", "Settings", "default_data_dir", "settings_table"]

ENV_PREFIX = "MICROBEARING_"


def default_data_dir() -> Path:
    """The per-user data folder of the service (``platformdirs.user_data_dir("microbearing")``)."""
    return Path(platformdirs.user_data_dir("microbearing"))


class Settings(BaseSettings):
    """Configuration of one service instance; immutable once the app is built."""

    # Errors name the setting and the rule, not the value given: it may hold a password or a key.
    model_config = SettingsConfigDict(env_prefix=ENV_PREFIX, frozen=True, extra="forbid",
                                      hide_input_in_errors=True)

    data_dir: Path = Field(
        default_factory=default_data_dir,
        description="Folder holding the SQLite database of jobs and stored models (with "
                    "MICROBEARING_DATABASE_URL they are in PostgreSQL, and the folder holds this host's "
                    "metrics files only).",
    )
    database_url: SecretStr = Field(
        default=SecretStr(""),
        description="PostgreSQL database of jobs and stored models (postgresql://user:password@host:5432/"
                    "name), shared by server processes on several hosts; needs the postgres extra (pip "
                    "install 'microbearing[postgres]'). Empty: SQLite in MICROBEARING_DATA_DIR (one host).",
    )
    database_pool_size: int = Field(
        default=8, ge=1, le=256,
        description="Most connections one server process opens to the PostgreSQL database [1] (with "
                    "MICROBEARING_DATABASE_URL).",
    )
    database_timeout_s: float = Field(
        default=10.0, gt=0, le=600,
        description="How long a request or job waits to open a PostgreSQL connection, or for a free one of "
                    "the pool [s]; then 503 naming the database (with MICROBEARING_DATABASE_URL).",
    )
    max_body_bytes: int = Field(
        default=256 * 2**20, ge=1024,
        description="Largest accepted request body [bytes]; larger bodies get 413.",
    )
    max_document_bytes: int = Field(
        default=64 * 2**20, ge=1024,
        description="Largest body of a request that sends a document, not columns of data (a sweep, "
                    "optimization, surrogate, experiment design, next experiments, one friction point, a "
                    "calibration's JSON) [bytes]; a larger one gets 413 while it streams in. The routes of "
                    "data columns (/v1/friction/batch, a surrogate's predict, the CSV uploads, UM-Bridge) "
                    "take up to MICROBEARING_MAX_BODY_BYTES.",
    )
    max_field_bytes: int = Field(
        default=2**20, ge=1024,
        description="Longest string, number or run of spaces of a JSON body and longest line of a CSV body "
                    "[bytes]; a body with a longer one gets 413 while it streams in, before it is held or "
                    "parsed.",
    )
    max_batch_points: int = Field(
        default=2_000_000, ge=1,
        description="Most points in one /v1/friction/batch request; more get 413.",
    )
    max_sweep_points: int = Field(
        default=2_000_000, ge=1,
        description="Most points in one sweep; larger designs get 422.",
    )
    max_heavy_requests: int = Field(
        default=2, ge=1, le=64,
        description="Most requests with a body over 1 MiB (or of undeclared size) in progress in one server "
                    "process; more wait for their turn before their body is read. Each also holds a place "
                    "of MICROBEARING_MAX_ACTIVE_JOBS (and ..._PER_KEY). A 2e6-point batch with every output "
                    "takes about 0.5 GB: this bounds the memory of large requests.",
    )
    heavy_request_wait_s: float = Field(
        default=30.0, ge=0, le=600,
        description="How long a request with a body over 1 MiB waits for its turn [s]; then 503 with "
                    "Retry-After.",
    )
    sweep_sync_max_points: int = Field(
        default=10_000, ge=0,
        description="Sweeps of at most this many points answer 200 at once; larger ones run as jobs (202).",
    )
    job_workers: int = Field(
        default=2, ge=1, le=64,
        description="Background threads running jobs in each server process.",
    )
    # Admission control, retention and storage (service/jobs.py, service/store.py).
    max_active_jobs: int = Field(
        default=64, ge=1,
        description="Most queued and running jobs of the database (the data folder's, or PostgreSQL's), "
                    "counted over every server process sharing it; a job request past it gets 503 with "
                    "Retry-After. A queued job holds only its request (designs are built as it starts).",
    )
    max_active_jobs_per_key: int = Field(
        default=16, ge=1,
        description="Most queued and running jobs of one API key, counted over every server process sharing "
                    "the database; past it 429 with Retry-After. Applies only when MICROBEARING_API_KEYS "
                    "is set.",
    )
    job_lease_s: float = Field(
        default=15.0, ge=1.0, le=3600.0,
        description="Lease of a running job [s], renewed by its server process every third of it: a job "
                    "whose process stopped renewing it is re-queued (or failed: /manual/how-to/operations/) "
                    "by another process within 4/3 of this; on one host a dead process's jobs within a third "
                    "of it.",
    )
    shutdown_grace_s: float = Field(
        default=10.0, ge=0.0, le=3600.0,
        description="On SIGTERM, running jobs may finish for this long [s]; those still running are then "
                    "stopped and re-queued (queued jobs stay queued for the next start or another process).",
    )
    max_result_bytes: int = Field(
        default=128 * 2**20, ge=1024,
        description="Largest stored result of one job [bytes] (its JSON); a sweep predicted to exceed it "
                    "gets 413, a job whose result does fails with a 413 problem.",
    )
    job_retention_s: float = Field(
        default=7 * 24 * 3600.0, gt=0,
        description="Finished jobs and their results are deleted this long after they finished [s] "
                    "(7 days). Stored surrogates and calibrations do not expire.",
    )
    max_stored_models: int = Field(
        default=10_000, ge=1,
        description="Most stored models (calibrations and surrogates together) the data folder or database "
                    "holds [1]: a request that would store one more gets 507 naming this setting, and a job "
                    "that reaches it meanwhile fails with that problem. Delete models no longer needed.",
    )
    min_free_bytes: int = Field(
        default=64 * 2**20, ge=0,
        description="GET /readyz answers 503 when the data folder's file system has less free space [bytes].",
    )
    max_calibration_rows: int = Field(
        default=20_000, ge=1,
        description="Most data rows of one calibration (JSON or CSV); more get 413.",
    )
    max_calibration_columns: int = Field(
        default=64, ge=1, le=10_000,
        description="Most columns of one calibration's data (JSON keys over all rows, or the CSV header's "
                    "columns); more get 413 before the data are parsed.",
    )
    model_cache_size: int = Field(
        default=16, ge=0, le=1024,
        description="Calibrated models and surrogates kept rebuilt in memory (the most recently used), so "
                    "that one point per request does not rebuild its model each time; 0 keeps none.",
    )
    body_timeout_s: float = Field(
        default=60.0, gt=0,
        description="Time allowed to receive a whole request body [s]; a slower body gets 408.",
    )
    # Connections (service/connections.py; the header limits and the connection cap apply under
    # `microbearing serve`, whose uvicorn runs connections.BoundedHttpProtocol).
    header_timeout_s: float = Field(
        default=10.0, gt=0, le=3600,
        description="Time allowed for a request line and its headers [s], from the connection's opening or "
                    "the previous answer; a connection that has not sent them by then is closed.",
    )
    max_header_bytes: int = Field(
        default=32 * 2**10, ge=1024, le=2**24,
        description="Largest request line and headers [bytes]; larger ones get 431 and the connection is "
                    "closed.",
    )
    max_connections: int = Field(
        default=10_000, ge=1,
        description="Most open connections of one server process [1], lowered to the open-file limit less "
                    "MICROBEARING_FD_RESERVE; a connection past it closes the oldest one still waiting for "
                    "its request head.",
    )
    fd_reserve: int = Field(
        default=512, ge=64,
        description="File descriptors kept free of client connections [1], for the database, logs, the dask "
                    "client and connections accepted in a burst (the listen backlog is a quarter of it). The "
                    "open-file soft limit is raised to the hard limit at start.",
    )
    max_concurrent_requests: int = Field(
        default=256, ge=1,
        description="Most requests in progress in one server process [1]; past it 503 with Retry-After "
                    "(/healthz and /readyz always answer).",
    )
    # Reliability and scale-out (service/security.py, service/executor.py).
    api_keys: SecretStr = Field(
        default=SecretStr(""),
        description="Comma-separated API keys; when set, every request except /healthz, /metrics and the "
                    "API docs needs `Authorization: Bearer <key>` (401 otherwise). Empty: no keys needed.",
    )
    admin_api_key: SecretStr = Field(
        default=SecretStr(""),
        description="An API key that sees, cancels and deletes the jobs, surrogates and calibrations of "
                    "every key (other keys see only their own). Empty: no admin key.",
    )
    dask_scheduler: str | None = Field(
        default=None,
        description="Run sweep and batch chunks and the groups of multi-start optimizations on "
                    "dask.distributed: a scheduler address (tcp://host:8786) or `local` for an embedded "
                    "LocalCluster. Unset: a local thread pool.",
    )
    dask_fault_timeout_s: float = Field(
        default=30.0, gt=0, le=3600,
        description="How long a dask scheduler may stay unreachable, or without workers, before the batch "
                    "or job waiting on it fails with 503 naming the scheduler [s]; chunks it dropped are "
                    "submitted again when it is back within this time. A worker without a heartbeat for "
                    "half this time (5 s at least) counts as not answering: a fault when no worker "
                    "answers or when it holds tasks.",
    )
    executor_workers: int = Field(
        default=0, ge=0, le=256,
        description="Threads running sweep and batch chunks and optimization groups (local pool or "
                    "embedded cluster); 0: one per CPU.",
    )
    physics_kernel: Literal["numpy", "numba"] = Field(
        default="numpy",
        description="Kernel of the physics evaluations of batches and sweeps: numpy, or numba (pip "
                    "install 'microbearing[fast]'), the same equation functions compiled (equal to numpy's "
                    "to 1e-12).",
    )
    physics_threads: int = Field(
        default=0, ge=0, le=256,
        description="Threads sharing one physics evaluation of 131,072 points or more [1] (batches and "
                    "sweeps run 65,536-point chunks on the MICROBEARING_EXECUTOR_WORKERS threads); 0: one "
                    "per usable CPU.",
    )

    @field_validator("physics_kernel")
    @classmethod
    def _kernel_installed(cls, value: str) -> str:
        if value == "numba" and not physics.compiled.AVAILABLE:
            raise ValueError("MICROBEARING_PHYSICS_KERNEL=numba needs numba: "
                             "pip install 'microbearing[fast]'")
        return value

    @field_validator("database_url")
    @classmethod
    def _postgresql_url(cls, value: SecretStr) -> SecretStr:
        url = value.get_secret_value().strip()
        if url and not url.startswith(("postgresql://", "postgres://")):
            raise ValueError("MICROBEARING_DATABASE_URL must be a PostgreSQL URL, postgresql://user:password@"
                             "host:5432/name, or empty for SQLite in MICROBEARING_DATA_DIR")
        return SecretStr(url)


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

"""The app the schemathesis tests run against, and their common settings.

Each test file builds its own app (:func:`build`) in its own data folder, so that pytest-xdist can run
the files in different workers, and closing one file's app never touches another's.
"""

from __future__ import annotations

import os
import tempfile

import schemathesis
from fastapi import FastAPI
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from microbearing.service.app import create_app
from microbearing.service.deps import close_runtime
from microbearing.service.settings import Settings

#: Generated requests per operation (25 keeps the suite within its ten minutes; raise it with
#: MICROBEARING_SCHEMATHESIS_EXAMPLES for a deeper search).
MAX_EXAMPLES = int(os.environ.get("MICROBEARING_SCHEMATHESIS_EXAMPLES", "25"))
#: CI draws the same examples on every run (a red build is then reproducible); developers' runs
#: draw new ones each time and so keep exploring.
DERANDOMIZE = os.environ.get("CI", "").lower() == "true"
#: What every response is checked for: no 5xx, and status, content type, body and headers as the spec says.
CHECKS = [schemathesis.checks.not_a_server_error, status_code_conformance, content_type_conformance,
          response_schema_conformance, response_headers_conformance]


class SpecApp:
    """An app with small limits (so generated requests also reach the 413 and job paths quickly),
    its data folder and its schema."""

    def __init__(self, prefix: str):
        self._data_dir = tempfile.TemporaryDirectory(prefix=prefix)
        self.app: FastAPI = create_app(Settings(
            data_dir=self._data_dir.name, max_batch_points=2_000, max_sweep_points=5_000,
            sweep_sync_max_points=50, max_body_bytes=1_000_000,
            max_active_jobs=1_000))  # generated jobs outnumber 64 when they finish slowly
        self.schema = schemathesis.openapi.from_asgi("/openapi.json", self.app)

    def close(self) -> None:
        close_runtime(self.app)
        self._data_dir.cleanup()

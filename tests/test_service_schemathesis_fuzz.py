"""Property-based tests of every operation against the API's own OpenAPI spec (schemathesis).

Every operation gets generated valid and invalid requests (schemathesis' examples, coverage and
fuzzing phases); the server must never answer 5xx and every response must match the spec (status
code, content type, body schema, headers). Slow tier (tests/tiers.py): schemathesis builds each
operation's coverage cases when it collects this file, so the quick tier does not collect it.
"""

from __future__ import annotations

import hypothesis
import pytest
from schemathesis_app import CHECKS, DERANDOMIZE, MAX_EXAMPLES, SpecApp

SPEC_APP = SpecApp("microbearing-schemathesis-fuzz-")
schema = SPEC_APP.schema


@pytest.fixture(scope="module", autouse=True)
def _close_app():
    yield
    SPEC_APP.close()


@schema.parametrize()
@hypothesis.settings(max_examples=MAX_EXAMPLES, deadline=None, derandomize=DERANDOMIZE,
                     suppress_health_check=list(hypothesis.HealthCheck))
def test_api_conforms_to_its_spec(case):
    case.call_and_validate(checks=CHECKS)

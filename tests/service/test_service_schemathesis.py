"""schemathesis over the published OpenAPI schema, against uvicorn over HTTP: no 5xx, and
responses conform to the schema (status codes, content types, bodies), for generated valid
(positive) and invalid (negative) requests on every operation.

(Driven through ``APIOperation.as_strategy`` + hypothesis: schemathesis' pytest plugin
``from_fixture`` does not run on pytest 9.) MOTIONX_SCHEMATHESIS_EXAMPLES sets the number
of examples per operation and mode (default 20).
"""

from __future__ import annotations

import os
import tempfile

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from schemathesis import GenerationMode
from svc_util import KEY_A

EXAMPLES = int(os.environ.get("MOTIONX_SCHEMATHESIS_EXAMPLES", "20"))


def _labels() -> list[str]:
    from service.app import create_app
    from service.config import Settings

    doc = create_app(Settings(data_dir=tempfile.gettempdir())).openapi()
    return [f"{m.upper()} {p}" for p, ops in doc["paths"].items() for m in ops]


@pytest.fixture(scope="module")
def api_schema(api):
    return schemathesis.openapi.from_url(api.base_url + "/openapi.json")


CASES = [
    pytest.param(label, mode, id=f"{label}-{mode.value}")
    for label in _labels()
    for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE)
    if not (label == "GET /health" and mode == GenerationMode.NEGATIVE)  # no input to make invalid
]


@pytest.mark.parametrize("label, mode", CASES)
def test_openapi_contract(api, api_schema, label, mode):
    op = api_schema.find_operation_by_label(label)
    assert op is not None, label

    @given(case=op.as_strategy(generation_mode=mode))
    @settings(max_examples=EXAMPLES, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large])
    def check(case):
        headers = {"X-API-Key": KEY_A}
        if case.headers:
            headers = {**case.headers, **headers}
        # positive_data_acceptance is left out: uploads and targets are also checked beyond
        # what a schema can say (frame widths = number of coordinates, known joints, eps <= delta0),
        # and those schema-valid requests rightly get 422 problem details.
        case.call_and_validate(base_url=api.base_url, headers=headers, timeout=30,
                               excluded_checks=[schemathesis.checks.positive_data_acceptance])

    check()

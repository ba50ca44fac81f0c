"""schemathesis over the published OpenAPI schema, against uvicorn over HTTP, on SQLite and on
PostgreSQL: no 5xx, and responses conform to the schema (status codes, content types, bodies),
for generated valid (positive) and invalid (negative) requests on every operation. Schema-valid
requests are accepted, except where the operation documents a 422 (tests/service/schemathesis.toml).

This is the short run of ``make test``; ``make fuzz`` (tests/service/fuzz.py) runs schemathesis'
own command line with every phase (examples, coverage, fuzzing, stateful) for 10,000+ cases per
database. (Driven through ``APIOperation.as_strategy`` + hypothesis: schemathesis' pytest plugin
``from_fixture`` does not run on pytest 9.) MOTIONX_SCHEMATHESIS_EXAMPLES sets the number of
examples per operation, mode and database (default 12).
"""

from __future__ import annotations

import os
import secrets
import tempfile
from pathlib import Path

import pytest
import schemathesis
from conftest import start_api_process
from hypothesis import HealthCheck, given, settings
from schemathesis import GenerationMode
from schemathesis.config import SchemathesisConfig
from svc_util import KEY_A

from service.topology import create_postgres_database, drop_postgres_database

EXAMPLES = int(os.environ.get("MOTIONX_SCHEMATHESIS_EXAMPLES", "12"))
CONFIG = Path(__file__).with_name("schemathesis.toml")


def _labels() -> list[str]:
    from service.app import create_app
    from service.config import Settings

    doc = create_app(Settings(data_dir=tempfile.gettempdir())).openapi()
    return [f"{m.upper()} {p}" for p, ops in doc["paths"].items() for m in ops]


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def target(request, tmp_path_factory):
    env, name = {"MOTIONX_JOB_TIME_LIMIT_S": "20"}, None
    if request.param == "postgresql":
        admin = request.getfixturevalue("pg_admin")
        name = f"motionx_schemathesis_{secrets.token_hex(4)}"
        env["DATABASE_URL"] = create_postgres_database(admin, name, exist_ok=False)
    api = start_api_process(tmp_path_factory.mktemp(f"schemathesis-{request.param}"), env)
    schema = schemathesis.openapi.from_url(api.base_url + "/openapi.json",
                                           config=SchemathesisConfig.from_path(CONFIG))
    yield api, schema
    api.close()
    api.proc.stop()
    log = api.proc.log_text()
    for sign in ("unhandled error on", "Exception in ASGI application", "compute process failed"):
        assert sign not in log, log[log.index(sign) - 200:][:3000]
    if name:
        drop_postgres_database(request.getfixturevalue("pg_admin"), name)


CASES = [
    pytest.param(label, mode, id=f"{label}-{mode.value}")
    for label in _labels()
    for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE)
    if not (label in ("GET /health", "GET /axes", "GET /usage") and mode == GenerationMode.NEGATIVE)  # no input
]


@pytest.mark.parametrize("label, mode", CASES)
def test_openapi_contract(target, label, mode):
    api, schema = target
    op = schema.find_operation_by_label(label)
    assert op is not None, label

    @given(case=op.as_strategy(generation_mode=mode))
    @settings(max_examples=EXAMPLES, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large])
    def check(case):
        headers = {"X-API-Key": KEY_A}
        if case.headers:
            headers = {**case.headers, **headers}
        case.call_and_validate(base_url=api.base_url, headers=headers, timeout=60)

    check()

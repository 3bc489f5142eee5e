"""Property-based tests of the whole API against its own OpenAPI document (schemathesis): for
every operation, generated valid and invalid requests never get a 5xx, and every answer
matches the documented status codes, content types, headers and schemas. The database holds
data, so pages, exports and the feed are not trivially empty."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import schemathesis
from fastapi import FastAPI
from hypothesis import HealthCheck, given, settings
from schemathesis.specs.openapi.checks import positive_data_acceptance

from tests.gateway.helpers import (
    ADMIN_KEY,
    ROOT,
    SITE,
    car_batches,
    devices_state,
    gateway_settings,
    open_storage,
    sample_alert,
    service_status,
)
from tests.gateway.test_queue import state as queue_state
from wz_gateway.app import create_app
from wz_shared.messages import (
    AlertType,
    CalibrationState,
    Message,
    PoseCorrection,
    SensorCalibration,
)


@pytest.fixture(scope="module")
def gateway_app(tmp_path_factory: pytest.TempPathFactory) -> Iterator[FastAPI]:
    gateway = gateway_settings(
        tmp_path_factory.mktemp("openapi"),
        max_page_size=200,
        rate_limit_per_s=1e6,
        rate_limit_burst=1_000_000,
    )
    storage = open_storage(gateway)
    messages: list[Message] = [
        *car_batches(1, 900.0, 25.0, 0.0, 60),
        *car_batches(2, 905.0, 20.0, 0.0, 60, offset_m=1.83),
    ]
    messages += [sample_alert(f"a{k}", float(k)) for k in range(5)]
    messages += [
        devices_state(5.0, beacon_on=True, sign_text="SLOW DOWN", cause=AlertType.SPEEDING),
        service_status("alert-service", 5.0, {}),
        queue_state(5.0, 900.0, stopped=True),
        SensorCalibration(
            site=SITE.site_id,
            source_id="camera-mast",
            stamp=5.0,
            sensor_kind="camera",
            state=CalibrationState.BUMPED,
            state_since_s=4.0,
            correction=PoseCorrection(yaw_deg=1.2, yaw_std_deg=0.4),
            clock_offset_s=0.08,
            detail="yaw moved 1.2 deg within 4 s",
        ),
    ]
    storage.ingest(messages, geo=SITE.geo_frame, received_at=1_750_000_000.0)
    yield create_app(gateway, storage, site=SITE)
    storage.close()


@pytest.mark.parametrize("mode", list(schemathesis.GenerationMode), ids=str)
def test_every_operation_conforms_and_never_fails_on_the_server(
    gateway_app: FastAPI, mode: schemathesis.GenerationMode
) -> None:
    """Positive mode: schema-valid requests; negative mode: invalid ones, which must be refused
    with a documented 4xx. Every check but ``positive_data_acceptance``: what OpenAPI cannot
    say (``start`` after ``end``, a cursor the API never gave out, a page larger than this
    deployment's ``max_page_size``) is valid to the schema and rightly refused with 422."""
    api = schemathesis.openapi.from_asgi("/openapi.json", gateway_app)
    # The live stream never ends: tests/gateway/test_stream.py checks it.
    operations = [
        op for op in (result.ok() for result in api.get_all_operations()) if op.path != "/v1/stream"
    ]
    assert len(operations) == 18 + 7  # 7: /v1/webhooks
    checked = 0
    for operation in operations:
        has_input = any(True for _ in operation.iter_parameters()) or bool(
            operation.get_request_payload_content_types()
        )
        if mode is schemathesis.GenerationMode.NEGATIVE and not has_input:
            continue  # nothing to make invalid

        @given(case=operation.as_strategy(generation_mode=mode))
        @settings(
            max_examples=30,
            deadline=None,
            database=None,
            derandomize=True,
            suppress_health_check=list(HealthCheck),
        )
        def check(case: Any) -> None:
            case.call_and_validate(
                headers={"X-API-Key": ADMIN_KEY}, excluded_checks=[positive_data_acceptance]
            )

        check()
        checked += 1
    assert checked >= 6


def test_the_committed_document_is_what_the_app_serves(tmp_path: Path) -> None:
    """services/gateway/openapi.json (what a client generator or a dashboard team reads) is
    the app's own document; a stale copy is caught with what to run."""
    committed = ROOT / "services" / "gateway" / "openapi.json"
    check = [sys.executable, "-m", "wz_gateway.openapi_doc", "--check"]
    result = subprocess.run([*check, str(committed)], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr
    stale = tmp_path / "openapi.json"
    stale.write_text(committed.read_text().replace('"/v1/alerts"', '"/v1/alarms"'))
    result = subprocess.run([*check, str(stale)], capture_output=True, text=True, check=False)
    assert result.returncode == 1 and "--write" in result.stderr

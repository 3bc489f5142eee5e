"""API keys over real HTTP on real SQLite files: keys made in dev mode do not outlive it (also
in a database from before they were marked), and the number of live keys is capped."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import httpx
import pytest
from pydantic import ValidationError
from sqlalchemy import create_engine, insert

from tests.gateway.helpers import (
    ADMIN_KEY,
    gateway_settings,
    live_server,
    mint_concurrently,
    open_storage,
)
from wz_gateway.auth import check_secret, new_secret
from wz_gateway.key_store import KeyStore
from wz_gateway.node import prepare_keys
from wz_gateway.settings import GatewaySettings
from wz_gateway.storage import Storage
from wz_gateway.tables import MIGRATIONS, SCHEMA_VERSION, api_keys, schema_version

ADMIN = {"X-API-Key": ADMIN_KEY}


def mint(url: str, headers: dict[str, str], scope: str = "admin") -> httpx.Response:
    return httpx.post(
        f"{url}/v1/admin/api-keys", headers=headers, json={"scope": scope, "name": "n"}
    )


def test_keys_made_in_dev_mode_are_revoked_when_it_ends(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Not only the dev admin key: those it (or a configured key) made through the API, too;
    keys made outside dev mode stay."""
    dev = GatewaySettings(data_dir=tmp_path / "data", dev_mode=True)  # as gateway_settings
    storage = Storage.open(dev.resolved_database_url())
    dev_secret = prepare_keys(storage, dev, time.time())
    assert dev_secret is not None
    with live_server(dev, storage) as url:
        made = [mint(url, {"X-API-Key": dev_secret}, scope) for scope in ("admin", "read")]
        assert [m.status_code for m in made] == [201, 201]
        assert all(m.json()["dev_mode"] for m in made)
    storage.close()

    production = gateway_settings(tmp_path)
    storage = Storage.open(production.resolved_database_url())
    with caplog.at_level(logging.WARNING, logger="wz_gateway.node"):
        prepare_keys(storage, production, time.time())
    assert "3 API keys made in dev mode revoked" in caplog.text
    with live_server(production, storage) as url:
        for secret in (dev_secret, *(m.json()["secret"] for m in made)):
            assert httpx.get(f"{url}/v1/site", headers={"X-API-Key": secret}).status_code == 401
        kept = mint(url, ADMIN)
        assert kept.status_code == 201 and not kept.json()["dev_mode"]
    storage.close()

    storage = open_storage(production)  # another start: nothing more to revoke
    live = KeyStore(storage.engine).all()
    assert kept.json()["key_id"] in {k.key_id for k in live}
    assert not any(k.dev_mode for k in live)
    storage.close()


def test_migration_6_marks_the_keys_older_dev_runs_made(tmp_path: Path) -> None:
    """A database at schema 5: a dev run (its dev key live from 100 s to 200 s) made a key at
    150 s; a key made at 300 s, outside it, and a settings key are not marked."""
    path = tmp_path / "gateway.sqlite3"
    engine = create_engine(f"sqlite:///{path}")
    with engine.begin() as connection:
        schema_version.create(connection)
        for migration in MIGRATIONS[:5]:
            migration.apply(connection)
            connection.execute(
                insert(schema_version).values(
                    version=migration.version, description=migration.description, applied_at=0.0
                )
            )
        rows = [
            ("dev0", "dev", 100.0, 200.0),
            ("api-in-dev", "api", 150.0, None),
            ("api-later", "api", 300.0, None),
            ("settings", "settings", 120.0, None),
        ]
        for key_id, origin, created_at, revoked_at in rows:
            connection.execute(
                insert(api_keys).values(
                    key_id=key_id,
                    fingerprint="00000000",
                    salt="00",
                    secret_hash="00",
                    scope="admin",
                    name=key_id,
                    origin=origin,
                    created_at=created_at,
                    revoked_at=revoked_at,
                )
            )
    engine.dispose()
    storage = Storage.open(f"sqlite:///{path}")
    assert storage.current_schema_version() == SCHEMA_VERSION
    marked = {k.key_id: k.dev_mode for k in KeyStore(storage.engine).all(include_revoked=True)}
    assert marked == {"dev0": True, "api-in-dev": True, "api-later": False, "settings": False}
    assert KeyStore(storage.engine).revoke_dev_mode(400.0) == 1  # dev0 was revoked already
    storage.close()


def test_making_a_key_beyond_the_limit_gets_409(tmp_path: Path) -> None:
    """Two configured keys and a limit of 3: one more can be made, then 409 (never a 5xx);
    revoking one makes room again."""
    settings = gateway_settings(tmp_path, max_api_keys=3)
    storage = open_storage(settings)
    with live_server(settings, storage) as url:
        made = mint(url, ADMIN)
        assert made.status_code == 201, made.text
        refused = mint(url, ADMIN)
        assert refused.status_code == 409, refused.text
        assert refused.headers["content-type"] == "application/problem+json"
        assert "3 API keys are live, the most allowed is 3" in refused.json()["detail"]
        assert KeyStore(storage.engine).count_live() == 3
        key_id = made.json()["key_id"]
        assert httpx.delete(f"{url}/v1/admin/api-keys/{key_id}", headers=ADMIN).status_code == 204
        assert mint(url, ADMIN).status_code == 201
    storage.close()


def test_concurrent_key_creations_never_pass_the_cap(tmp_path: Path) -> None:
    """60 creations at once against a cap of 20 (two keys configured): exactly 18 made, the
    rest refused with 409, 20 live (the count and the insert were two statements: 32-34)."""
    settings = gateway_settings(tmp_path, max_api_keys=20)
    storage = open_storage(settings)
    with live_server(settings, storage) as url:
        codes = mint_concurrently(url, ADMIN, 60)
    assert sorted(set(codes)) == [201, 409], codes
    assert codes.count(201) == 18 and codes.count(409) == 42
    assert KeyStore(storage.engine).count_live() == 20
    storage.close()


@pytest.mark.parametrize(
    "secret",
    [
        "changeme",
        " CHANGE-ME ",
        "Change_Me!",
        "'changeme'",
        "<your-key-here>",
        "<Your API Key>",
        "[YOUR_SECRET_HERE]",
        "{{ placeholder }}",
        "change-me-change-me-change-me",
        "Please-ChangeMe-0123456789",
        "replace-me-with-a-real-key-123",
        "wzk_XXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXXX",
        "xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx",
        "a" * 40,
        "ab" * 20,
        "secretsecretsecretsecret",
        "abc123abc123abc123abc123x",  # a part repeated, then one more: still too repetitive
        "PASSWORD",
        "wzk_short",
        "0123456701234567012345670",
    ],
)
def test_placeholder_and_weak_secrets_are_refused(secret: str) -> None:
    with pytest.raises(ValidationError, match=r"placeholder|characters|repetitive"):
        GatewaySettings(data_dir=Path("/nonexistent"), api_keys=[f"admin:{secret}"])


@pytest.mark.parametrize(
    "secret",
    [ADMIN_KEY, new_secret(), "Tr0ub4dor-and-3-horses-9x"],
    # A fresh secret each collection: ids that do not change, so the workers of pytest-xdist
    # collect the same tests.
    ids=["configured", "new", "passphrase"],
)
def test_real_secrets_pass(secret: str) -> None:
    check_secret(secret)

"""The API keys in the database (table ``api_keys``), and the app's cache of verified keys.

A key's secret never reaches the disk: each row holds its ``key_id``, ``fingerprint``, salt and
scrypt hash (see :mod:`wz_gateway.auth`). Keys come from three places (``origin``): the
settings (kept in step with them at each start by :meth:`KeyStore.sync_configured`), the
admin routes (``api``) and dev mode (``dev``). Every key made while the gateway runs in dev
mode (the dev admin key, and keys made through the API then) is marked ``dev_mode``, and
:meth:`KeyStore.revoke_dev_mode` revokes them all when the gateway starts outside dev mode. The
same database as :class:`Storage`: build it on ``storage.engine``.

Usage::

    keys = KeyStore(storage.engine)
    info = keys.add("read", auth.new_secret(), name="dashboard", origin="api", now=time.time())
"""

from __future__ import annotations

import hashlib
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import Engine, func, insert, literal, select, text, update

from wz_gateway import auth
from wz_gateway.models import ApiKeyInfo, KeyOrigin
from wz_gateway.tables import api_keys

#: How long the app trusts a verified key before asking the database again [s].
KEY_CACHE_S = 30.0


class KeyLimitError(Exception):
    """The live keys are at the limit: revoke one before making another."""


class KeyStore:
    """Add, find, list and revoke API keys. Thread-safe (a connection per call)."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def add(
        self,
        scope: auth.Scope,
        secret: str,
        *,
        name: str,
        origin: KeyOrigin,
        now: float,
        dev_mode: bool = False,
        max_live: int | None = None,
    ) -> ApiKeyInfo:
        """Store a key's hash; the secret itself is not kept.

        Raises
        ------
        KeyLimitError
            If ``max_live`` keys (or more) are live already; nothing is stored.
        """
        salt = auth.new_salt()
        info = ApiKeyInfo(
            key_id=auth.new_key_id(),
            scope=scope,
            name=name,
            origin=origin,
            created_at=now,
            dev_mode=dev_mode,
        )
        values = {
            "key_id": info.key_id,
            "fingerprint": auth.fingerprint(secret),
            "salt": salt,
            "secret_hash": auth.hash_secret(secret, salt),
            "scope": scope,
            "name": name,
            "origin": origin,
            "created_at": now,
            "dev_mode": dev_mode,
        }
        with self.engine.begin() as connection:
            if max_live is None:
                connection.execute(insert(api_keys).values(**values))
                return info
            # The count and the insert are one statement, so two requests cannot both see
            # room for one more key. SQLite runs a writing statement under its write lock
            # from its start; PostgreSQL (read committed) lets two transactions count alike,
            # so each first takes a lock that key creations share with nobody (reads go on).
            if connection.dialect.name == "postgresql":
                connection.execute(text("LOCK TABLE api_keys IN SHARE ROW EXCLUSIVE MODE"))
            room = (
                select(func.count())
                .select_from(api_keys)
                .where(api_keys.c.revoked_at.is_(None))
                .scalar_subquery()
                < max_live
            )
            row = select(*(literal(v, api_keys.c[k].type).label(k) for k, v in values.items()))
            inserted = connection.execute(
                insert(api_keys)
                .from_select(list(values), row.where(room))
                .returning(api_keys.c.key_id)
            ).first()
            if inserted is None:
                live = self._count_live(connection)
                raise KeyLimitError(
                    f"{live} API keys are live, the most allowed is {max_live} "
                    "(WZ_GATEWAY_MAX_API_KEYS): revoke keys no longer used first"
                )
        return info

    def count_live(self) -> int:
        """How many keys are not revoked."""
        with self.engine.connect() as connection:
            return self._count_live(connection)

    @staticmethod
    def _count_live(connection: Any) -> int:
        stmt = select(func.count()).select_from(api_keys).where(api_keys.c.revoked_at.is_(None))
        return int(connection.execute(stmt).scalar_one())

    def revoke_dev_mode(self, now: float) -> int:
        """Revoke every live key made in dev mode; how many were."""
        c = api_keys.c
        with self.engine.begin() as connection:
            outcome = connection.execute(
                update(api_keys)
                .where(c.dev_mode.is_(True), c.revoked_at.is_(None))
                .values(revoked_at=now)
            )
        return int(outcome.rowcount)

    def find(self, secret: str) -> ApiKeyInfo | None:
        """The live (not revoked) key whose secret this is, or None."""
        c = api_keys.c
        with self.engine.connect() as connection:
            rows = connection.execute(
                select(api_keys).where(
                    c.fingerprint == auth.fingerprint(secret), c.revoked_at.is_(None)
                )
            ).all()
        for row in rows:
            if auth.verify_secret(secret, row.salt, row.secret_hash):
                return _key_info(row)
        return None

    def all(self, *, include_revoked: bool = False) -> list[ApiKeyInfo]:
        """Every live key (and the revoked ones too if asked), oldest first."""
        stmt = select(api_keys).order_by(api_keys.c.id)
        if not include_revoked:
            stmt = stmt.where(api_keys.c.revoked_at.is_(None))
        with self.engine.connect() as connection:
            return [_key_info(row) for row in connection.execute(stmt)]

    def revoke(self, key_id: str, now: float) -> bool:
        """Revoke a key (its row stays, marked); False if there is no such live key."""
        c = api_keys.c
        with self.engine.begin() as connection:
            outcome = connection.execute(
                update(api_keys)
                .where(c.key_id == key_id, c.revoked_at.is_(None))
                .values(revoked_at=now)
            )
        return bool(outcome.rowcount)

    def sync_configured(
        self, configured: Sequence[tuple[auth.Scope, str]], now: float
    ) -> tuple[int, int]:
        """Make the ``settings`` keys those configured: add the new, revoke the dropped.

        Returns
        -------
        added, revoked : int
        """
        c = api_keys.c
        with self.engine.connect() as connection:
            rows = connection.execute(
                select(api_keys).where(c.origin == "settings", c.revoked_at.is_(None))
            ).all()
        kept: set[str] = set()
        added = 0
        for number, (scope, secret) in enumerate(configured, start=1):
            match = next(
                (
                    row
                    for row in rows
                    if row.key_id not in kept
                    and row.scope == scope
                    and row.fingerprint == auth.fingerprint(secret)
                    and auth.verify_secret(secret, row.salt, row.secret_hash)
                ),
                None,
            )
            if match is not None:
                kept.add(match.key_id)
                continue
            info = self.add(
                scope, secret, name=f"settings key {number}", origin="settings", now=now
            )
            kept.add(info.key_id)
            added += 1
        revoked = sum(self.revoke(row.key_id, now) for row in rows if row.key_id not in kept)
        return added, revoked


@dataclass
class KeyCache:
    """Verified keys for ``ttl_s`` (scrypt is slow on purpose); cleared when a key is revoked."""

    store: KeyStore
    ttl_s: float = KEY_CACHE_S
    clock: Callable[[], float] = time.monotonic
    _entries: dict[str, tuple[ApiKeyInfo, float]] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def verify(self, secret: str) -> ApiKeyInfo | None:
        digest = hashlib.sha256(secret.encode()).hexdigest()
        now = self.clock()
        with self._lock:
            cached = self._entries.get(digest)
        if cached is not None and cached[1] > now:
            return cached[0]
        info = self.store.find(secret)
        with self._lock:
            if info is None:
                self._entries.pop(digest, None)
            else:
                if len(self._entries) > 10_000:
                    self._entries.clear()
                self._entries[digest] = (info, now + self.ttl_s)
        return info

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()


def _key_info(row: Any) -> ApiKeyInfo:
    return ApiKeyInfo(
        key_id=row.key_id,
        scope=row.scope,
        name=row.name,
        origin=row.origin,
        created_at=row.created_at,
        revoked_at=row.revoked_at,
        dev_mode=bool(row.dev_mode),
    )

"""API keys and rate limits, without I/O.

A key is a secret string; the gateway stores, per key, a short public ``key_id`` (to list and
revoke it), the key's ``fingerprint`` (the first 8 hex digits of its SHA-256: enough to find
its row, far too short to confirm a guess offline) and its scrypt hash with a per-key salt. A
presented key is hashed only when a stored fingerprint matches, so a flood of made-up keys
costs one SHA-256 each, not an scrypt.

Scopes are ordered: ``admin`` can do whatever ``read`` can.
"""

from __future__ import annotations

import hashlib
import hmac
import math
import secrets
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Literal, get_args

Scope = Literal["read", "admin"]
SCOPES: tuple[Scope, ...] = get_args(Scope)
_RANK: dict[Scope, int] = {"read": 1, "admin": 2}
#: Keys the gateway makes: this prefix, then 43 URL-safe characters (256 random bits).
KEY_PREFIX = "wzk_"
MIN_SECRET_CHARS = 24
#: Fewest different characters a secret must hold (``wzk_`` keys hold about 30).
MIN_DISTINCT_CHARS = 8
# Words of examples and templates, compared once case, separators and brackets are gone
# (``<Your-API-Key>`` is ``yourapikey``): never accepted, however long.
_KNOWN_SECRETS = frozenset(
    [
        "changeme",
        "secret",
        "password",
        "passwd",
        "admin",
        "default",
        "example",
        "test",
        "token",
        "apikey",
        "key",
        "placeholder",
        "replaceme",
        "yourkeyhere",
        "yourapikey",
        "yourapikeyhere",
        "yoursecret",
        "yoursecrethere",
        "yourtoken",
        "yourpassword",
        "secretkey",
        "mysecret",
        "insertkeyhere",
        "dummy",
        "sample",
        "todo",
        "fixme",
        "null",
        "none",
        "letmein",
        "qwerty",
        "123456",
        "12345678",
        "1234567890",
    ]
)
# Parts that only a template holds, wherever they are in it (eight x: one random key in about
# a billion holds them).
_TEMPLATE_MARKERS = ("changeme", "replaceme", "placeholder", "yourkey", "yoursecret", "x" * 8)
_SEPARATORS = str.maketrans("", "", " \t-_.:;,/|'\"`<>[](){}*#$!?")
# scrypt cost: n = 2^14, r = 8 (16 MiB, about 30 ms): a stolen database does not give up a
# hand-made key quickly; each verified key is cached by the app, so requests do not pay it.
_SCRYPT_N = 1 << 14
_SCRYPT_R = 8
_SCRYPT_P = 1


def scope_allows(granted: Scope, needed: Scope) -> bool:
    """Whether a key of scope ``granted`` may do what needs ``needed``."""
    return _RANK[granted] >= _RANK[needed]


def new_secret() -> str:
    """A new random key: ``wzk_`` and 256 random bits, URL-safe."""
    return KEY_PREFIX + secrets.token_urlsafe(32)


def new_key_id() -> str:
    """A public handle for a stored key (12 hex digits)."""
    return secrets.token_hex(6)


def new_salt() -> str:
    return secrets.token_hex(16)


def fingerprint(secret: str) -> str:
    """First 8 hex digits of SHA-256: finds a key's row, does not confirm a guess."""
    return hashlib.sha256(secret.encode()).hexdigest()[:8]


def hash_secret(secret: str, salt_hex: str) -> str:
    """scrypt of the key with its salt, hex."""
    digest = hashlib.scrypt(
        secret.encode(),
        salt=bytes.fromhex(salt_hex),
        n=_SCRYPT_N,
        r=_SCRYPT_R,
        p=_SCRYPT_P,
        dklen=32,
    )
    return digest.hex()


def verify_secret(secret: str, salt_hex: str, expected_hex: str) -> bool:
    """Whether ``secret`` hashes to ``expected_hex`` (constant-time comparison)."""
    return hmac.compare_digest(hash_secret(secret, salt_hex), expected_hex)


def check_secret(secret: str, where: str = "API key") -> None:
    """Refuse a secret that is a placeholder, too short, or too repetitive to guard anything.

    A placeholder in any dress: case, separators, brackets or quotes around it
    (``" Change_Me! "``, ``<your-key-here>``), a template marker inside it (``xxxx``,
    ``changeme-changeme-...``); too repetitive: fewer than :data:`MIN_DISTINCT_CHARS` distinct
    characters, or one short part repeated (``abc123abc123...``).

    Raises
    ------
    ValueError
        Naming ``where`` and what is wrong.
    """
    folded = secret.casefold()
    normal = folded.translate(_SEPARATORS)
    if (
        normal in _KNOWN_SECRETS
        or any(marker in normal for marker in _TEMPLATE_MARKERS)
        or (folded.strip().startswith("<") and folded.strip().endswith(">"))
    ):
        raise ValueError(
            f"{where}: the secret is a placeholder; make a real one "
            "(`python -m wz_gateway.keys` makes one)"
        )
    if len(secret) < MIN_SECRET_CHARS:
        raise ValueError(
            f"{where}: the secret has {len(secret)} characters, at least {MIN_SECRET_CHARS} are "
            "needed (`python -m wz_gateway.keys` makes one)"
        )
    if len(set(folded)) < MIN_DISTINCT_CHARS or _repeats(folded):
        raise ValueError(
            f"{where}: the secret is too repetitive (fewer than {MIN_DISTINCT_CHARS} different "
            "characters, or one part repeated); make a real one"
        )
    if any(ch.isspace() or ch == "," for ch in secret):
        raise ValueError(f"{where}: the secret may not hold spaces or commas")


def _repeats(text: str) -> bool:
    """Whether ``text`` is one part of at most a third of its length, repeated."""
    return any(
        text == (text[:size] * (len(text) // size + 1))[: len(text)]
        for size in range(1, len(text) // 3 + 1)
    )


def parse_configured_key(entry: str, where: str = "API key") -> tuple[Scope, str]:
    """Split a configured ``<scope>:<secret>`` into its scope and secret, checking both."""
    scope, sep, secret = entry.strip().partition(":")
    if not sep:
        raise ValueError(f"{where}: write it as <scope>:<secret>, scope one of {', '.join(SCOPES)}")
    if scope not in SCOPES:
        raise ValueError(f"{where}: scope {scope!r} is not one of {', '.join(SCOPES)}")
    check_secret(secret, where)
    return scope, secret


class TokenBuckets:
    """One token bucket per identity: ``rate_per_s`` tokens a second, at most ``burst`` held.

    Thread-safe. Holds at most ``max_identities`` buckets, forgetting the least recently used
    (a forgotten identity starts again with a full bucket).

    Parameters
    ----------
    rate_per_s : float
        Refill rate [tokens/s].
    burst : int
        Bucket size [tokens].
    clock : callable
        Monotonic time [s]; injectable for tests.
    """

    def __init__(
        self,
        rate_per_s: float,
        burst: int,
        *,
        clock: Callable[[], float] = time.monotonic,
        max_identities: int = 10_000,
    ) -> None:
        if rate_per_s <= 0 or burst < 1:
            raise ValueError("rate_per_s must be > 0 and burst >= 1")
        self.rate_per_s = rate_per_s
        self.burst = float(burst)
        self._clock = clock
        self._max = max_identities
        self._buckets: OrderedDict[str, tuple[float, float]] = OrderedDict()  # tokens, time
        self._lock = threading.Lock()

    def take(self, identity: str) -> float:
        """Spend one token; 0.0 if allowed, else the seconds until one is there."""
        now = self._clock()
        with self._lock:
            tokens, then = self._buckets.pop(identity, (self.burst, now))
            # tokens(t) = min(burst, tokens(then) + rate * (t - then))
            tokens = min(self.burst, tokens + self.rate_per_s * max(0.0, now - then))
            if tokens >= 1.0:
                self._buckets[identity] = (tokens - 1.0, now)
                wait_s = 0.0
            else:
                self._buckets[identity] = (tokens, now)
                wait_s = (1.0 - tokens) / self.rate_per_s
            while len(self._buckets) > self._max:
                self._buckets.popitem(last=False)
        return wait_s

    @staticmethod
    def retry_after_header(wait_s: float) -> str:
        """A ``Retry-After`` value: whole seconds, at least 1."""
        return str(max(1, math.ceil(wait_s)))

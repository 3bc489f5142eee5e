"""A real webhook receiver for the tests: ``http.server`` on a loopback port, in a thread.

It records every request (headers, body, when), checks its signature with the Standard
Webhooks reference library (``standardwebhooks``), and answers as the test says: a status and
headers per request, optionally after holding the request until the test lets it go (a receiver
slow to answer). Tests wait on what it received with a condition, not with sleeps.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import pytest
from standardwebhooks.webhooks import Webhook, WebhookVerificationError

from tests.conftest import free_port


@dataclass(frozen=True)
class Answer:
    """What the receiver answers: a status, headers, and whether to hold the request first."""

    status: int = 204
    headers: dict[str, str] = field(default_factory=dict)
    hold: bool = False


@dataclass(frozen=True)
class Received:
    """One request as the receiver saw it, and what it answered."""

    webhook_id: str
    headers: dict[str, str]
    body: bytes
    at: float  # time.monotonic() on arrival [s]
    status: int
    #: The standardwebhooks library accepted the signature (with the receiver's secrets).
    verified: bool
    path: str

    @property
    def ok(self) -> bool:
        return 200 <= self.status < 300


#: ``answer(webhook_id, seen_before)``: ``seen_before`` counts earlier requests with that id.
Policy = Callable[[str, int], Answer]


def always(status: int = 204) -> Policy:
    return lambda _id, _seen: Answer(status)


class Receiver:
    """Start with :meth:`start` (or as a context manager); ``url`` is where to subscribe.

    ``secrets`` are the signing secrets accepted (set once the subscription is made);
    ``policy`` may be changed at any time; ``release()`` lets held requests go.
    """

    def __init__(self, policy: Policy | None = None, *, port: int | None = None) -> None:
        self.port = port if port is not None else free_port()
        self.policy: Policy = policy if policy is not None else always()
        self.secrets: list[str] = []
        self.requests: list[Received] = []
        self._held: list[str] = []
        self._changed = threading.Condition()
        self._released = threading.Event()
        self._server: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        return self.url_for("/hooks/wz")

    def url_for(self, path: str) -> str:
        return f"http://127.0.0.1:{self.port}{path}"

    def verifies(self, body: bytes, headers: dict[str, str]) -> bool:
        """Whether the reference library accepts the signature with one of ``secrets``."""
        for secret in self.secrets:
            try:
                Webhook(secret).verify(body, headers)
                return True
            except WebhookVerificationError:
                continue
        return False

    def _handle(self, handler: BaseHTTPRequestHandler) -> None:
        length = int(handler.headers.get("content-length", "0"))
        body = handler.rfile.read(length)
        headers = {k.lower(): v for k, v in handler.headers.items()}
        webhook_id = headers.get("webhook-id", "")
        with self._changed:
            seen = sum(r.webhook_id == webhook_id for r in self.requests)
        answer = self.policy(webhook_id, seen)
        arrived = time.monotonic()
        if answer.hold:
            with self._changed:  # seen while held: tests wait for "in flight"
                self._held.append(webhook_id)
                self._changed.notify_all()
            self._released.wait()
        received = Received(
            webhook_id,
            headers,
            body,
            arrived,
            answer.status,
            self.verifies(body, headers),
            handler.path,
        )
        payload = b"" if answer.status == 204 else b'{"ok": false}'
        try:
            handler.send_response(answer.status)
            for name, value in answer.headers.items():
                handler.send_header(name, value)
            handler.send_header("content-length", str(len(payload)))
            handler.end_headers()
            handler.wfile.write(payload)
        finally:
            with self._changed:
                self.requests.append(received)
                self._changed.notify_all()

    def start(self) -> Receiver:
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"  # keep-alive, as real receivers

            def do_POST(self) -> None:
                receiver._handle(self)

            def log_message(self, format: str, *args: Any) -> None:
                pass

        self._server = ThreadingHTTPServer(("127.0.0.1", self.port), Handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)
        self._thread.start()
        return self

    def release(self) -> None:
        self._released.set()

    def stop(self) -> None:
        self.release()
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None

    def __enter__(self) -> Receiver:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # --- what was received ----------------------------------------------------------------

    def snapshot(self) -> list[Received]:
        with self._changed:
            return list(self.requests)

    def held(self) -> list[str]:
        with self._changed:
            return list(self._held)

    def wait_until(
        self, condition: Callable[[Receiver], bool], what: str, timeout_s: float = 20.0
    ) -> None:
        """Until ``condition(self)`` holds (checked at each request), or fail the test."""
        deadline = time.monotonic() + timeout_s
        with self._changed:
            while not condition(self):
                left = deadline - time.monotonic()
                if left <= 0:
                    pytest.fail(
                        f"timed out after {timeout_s:.0f} s waiting for {what}; "
                        f"received {len(self.requests)} requests"
                    )
                self._changed.wait(left)

    def delivered_ids(self) -> Counter[str]:
        """Requests answered 2xx, per webhook id."""
        return Counter(r.webhook_id for r in self.requests if r.ok)


def eventually(probe: Callable[[], Any], what: str, timeout_s: float = 20.0) -> Any:
    """Ask ``probe`` until it returns something truthy (the database has no event to wait on)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = probe()
        if value:
            return value
        time.sleep(0.02)
    pytest.fail(f"timed out after {timeout_s:.0f} s waiting for {what}")

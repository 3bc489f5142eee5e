"""The middlewares, outermost first: CORS (when origins are set; its headers on every
answer), :class:`HttpMetrics` (which counts the 413s too), :class:`BodySizeLimit`."""

from __future__ import annotations

import time

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from wz_gateway.api.errors import problem
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.settings import GatewaySettings


class BodySizeLimit:
    """Refuse request bodies over ``max_bytes`` with 413, whether announced or streamed."""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        announced = dict(scope.get("headers", [])).get(b"content-length")
        too_large = f"the request body is over the limit of {self.max_bytes} bytes"
        if announced is not None:
            try:
                length = int(announced)
            except ValueError:
                length = -1
            if length < 0:
                await problem(400, "Content-Length is not a number")(scope, receive, send)
                return
            if length > self.max_bytes:
                await problem(413, too_large)(scope, receive, send)
                return
        seen = 0

        async def counted() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_bytes:
                    raise HTTPException(413, too_large)  # the body reader passes it on
            return message

        await self.app(scope, counted, send)


class HttpMetrics:
    """Count requests by route template (not raw path: ids would explode the labels)."""

    def __init__(self, app: ASGIApp, metrics: GatewayMetrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        status = [500]

        async def watched(message: Message) -> None:
            if message["type"] == "http.response.start":
                status[0] = int(message["status"])
            await send(message)

        try:
            await self.app(scope, receive, watched)
        finally:
            route = scope.get("route")
            template = getattr(route, "path", None) or "unmatched"
            self.metrics.http_requests.labels(
                template, scope.get("method", ""), str(status[0])
            ).inc()
            self.metrics.http_latency.labels(template).observe(time.perf_counter() - started)


def add_middleware(app: FastAPI, settings: GatewaySettings, metrics: GatewayMetrics) -> None:
    """Add the middlewares. Each one added wraps the ones before: CORS outermost (its headers
    on every answer), then the metrics (which count the 413s too), then the body size limit."""
    app.add_middleware(BodySizeLimit, max_bytes=settings.max_body_bytes)
    app.add_middleware(HttpMetrics, metrics=metrics)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "DELETE"],
            allow_headers=["Authorization", "X-API-Key", "Content-Type"],
            expose_headers=["Link", "X-Next-Cursor", "Retry-After"],
            max_age=600,
        )

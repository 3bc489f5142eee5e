"""The webhook subscriptions' routes (admin), under ``/v1/webhooks``::

    POST   /v1/webhooks                       subscribe a URL; the signing secret is shown once
    GET    /v1/webhooks                       the subscriptions (without secrets)
    GET    /v1/webhooks/{id}                  one subscription
    DELETE /v1/webhooks/{id}                  unsubscribe (its pending events go with it)
    POST   /v1/webhooks/{id}/test             queue a ``webhook.test`` event for it
    POST   /v1/webhooks/{id}/rotate-secret    a new secret; the old one signs too for a while
    GET    /v1/webhooks/{id}/events           its newest events and where their delivery stands

A URL is refused (422) unless it is http(s) without credentials and its host resolves to
addresses the settings allow (public ones; see :func:`wz_gateway.delivery.address_policy`).
"""

from __future__ import annotations

import logging
import secrets
from typing import Annotated, Any

from fastapi import APIRouter, Path, Query
from fastapi.exceptions import RequestValidationError
from fastapi.responses import Response
from starlette.exceptions import HTTPException

from wz_gateway import webhooks
from wz_gateway.api.deps import Admin, Ctx, Webhooks
from wz_gateway.api.errors import V1_RESPONSES, problem_response
from wz_gateway.delivery import address_policy, check_url
from wz_gateway.models import (
    WEBHOOK_ID_PATTERN,
    CreatedWebhook,
    NewWebhook,
    WebhookEventInfo,
    WebhookInfo,
    WebhookSecret,
    WebhookTestEvent,
)

log = logging.getLogger(__name__)

SubscriptionId = Annotated[
    str, Path(pattern=WEBHOOK_ID_PATTERN, description="The subscription's id (`wh_...`)")
]
_NOT_FOUND: dict[int | str, dict[str, Any]] = {404: problem_response("No such subscription")}

router = APIRouter(prefix="/v1/webhooks", tags=["webhooks"], responses=V1_RESPONSES)


def _refuse_url(url: str, message: str) -> RequestValidationError:
    return RequestValidationError(
        [{"type": "value_error", "loc": ("body", "url"), "msg": message, "input": url}]
    )


def _found(info: Any, subscription_id: str) -> Any:
    if info is None:
        raise HTTPException(404, f"no webhook subscription {subscription_id}")
    return info


@router.post("", response_model=CreatedWebhook, status_code=201)
def create_webhook(context: Ctx, store: Webhooks, new: NewWebhook, caller: Admin) -> CreatedWebhook:
    """Subscribe a URL to alert events. Each event is POSTed as JSON
    ``{"type": "alert.<alert_type>", "timestamp": ..., "data": <the alert>}`` signed as
    Standard Webhooks say (headers ``webhook-id``, ``webhook-timestamp``,
    ``webhook-signature``). The signing secret is in this answer only."""
    url = new.url.strip()
    try:
        check_url(url, address_policy(context.settings))
    except webhooks.RefusedDestinationError as exc:
        raise _refuse_url(url, str(exc)) from exc
    secret = webhooks.new_secret()
    info = store.create(
        subscription_id=f"wh_{secrets.token_hex(8)}",
        url=url,
        secret=secret,
        event_types=new.event_types,
        min_severity=None if new.min_severity is None else new.min_severity.value,
        phases=None if new.phases is None else list(new.phases),
        description=new.description,
        now=context.clock(),
    )
    # The host only: a URL's path or query may hold the receiver's own token.
    log.info(
        "webhook %s to %s (%s) made by %s",
        info.subscription_id,
        webhooks.parse_destination(url).host,
        ", ".join(info.event_types),
        caller.key_id,
    )
    return CreatedWebhook(**info.model_dump(), secret=secret)


@router.get("", response_model=list[WebhookInfo])
def list_webhooks(store: Webhooks, _: Admin) -> list[WebhookInfo]:
    """Every subscription, without its secret."""
    return store.subscriptions()


@router.get("/{subscription_id}", response_model=WebhookInfo, responses=_NOT_FOUND)
def get_webhook(store: Webhooks, subscription_id: SubscriptionId, _: Admin) -> WebhookInfo:
    """One subscription (``disabled_at`` is set once its receiver answered 410 Gone)."""
    info: WebhookInfo = _found(store.get(subscription_id), subscription_id)
    return info


@router.delete("/{subscription_id}", status_code=204, responses=_NOT_FOUND)
def delete_webhook(store: Webhooks, subscription_id: SubscriptionId, caller: Admin) -> Response:
    """Unsubscribe: nothing more is sent; its undelivered events and its delivery log go."""
    if not store.delete(subscription_id):
        raise HTTPException(404, f"no webhook subscription {subscription_id}")
    log.info("webhook %s deleted by %s", subscription_id, caller.key_id)
    return Response(status_code=204)


@router.post(
    "/{subscription_id}/test",
    response_model=WebhookTestEvent,
    status_code=202,
    responses={**_NOT_FOUND, 409: problem_response("The subscription is disabled")},
)
def test_webhook(
    context: Ctx, store: Webhooks, subscription_id: SubscriptionId, _: Admin
) -> WebhookTestEvent:
    """Queue a ``webhook.test`` event for this subscription (whatever its filters); it is
    delivered, retried and logged as alerts are."""
    info = _found(store.get(subscription_id), subscription_id)
    if info.disabled_at is not None:
        raise HTTPException(
            409,
            f"webhook subscription {subscription_id} is disabled "
            f"({info.disabled_reason}); delete it and subscribe again",
        )
    event = webhooks.make_test_event(
        context.site.site_id, subscription_id, context.clock(), secrets.token_hex(12)
    )
    if not store.enqueue(subscription_id, event, context.clock()):
        raise HTTPException(404, f"no webhook subscription {subscription_id}")
    return WebhookTestEvent(
        subscription_id=subscription_id, event_id=event.event_id, event_type=event.event_type
    )


@router.post("/{subscription_id}/rotate-secret", response_model=WebhookSecret, responses=_NOT_FOUND)
def rotate_secret(
    context: Ctx, store: Webhooks, subscription_id: SubscriptionId, caller: Admin
) -> WebhookSecret:
    """A new signing secret, shown this once. Until ``previous_secret_until``
    (``webhook_secret_grace_s`` from now) every event carries two signatures, one per
    secret, so the receiver can switch when it likes."""
    secret = webhooks.new_secret()
    info = _found(
        store.rotate_secret(
            subscription_id,
            secret,
            now=context.clock(),
            grace_s=context.settings.webhook_secret_grace_s,
        ),
        subscription_id,
    )
    log.info("webhook %s secret rotated by %s", subscription_id, caller.key_id)
    return WebhookSecret(
        subscription_id=subscription_id,
        secret=secret,
        previous_secret_until=info.previous_secret_until,
    )


@router.get(
    "/{subscription_id}/events", response_model=list[WebhookEventInfo], responses=_NOT_FOUND
)
def list_events(
    store: Webhooks,
    subscription_id: SubscriptionId,
    _: Admin,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
) -> list[WebhookEventInfo]:
    """The subscription's newest events, newest first: state (pending, delivered, failed,
    expired), attempts, the last answer or error."""
    _found(store.get(subscription_id), subscription_id)
    return store.events(subscription_id, limit=limit)

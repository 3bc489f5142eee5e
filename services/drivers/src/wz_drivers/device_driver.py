"""The device driver: the alert service's roadside state onto a real message sign (NTCIP 1203).

``python -m wz_drivers.device_driver`` (service ``device-driver``) follows
``wz/<site>/devices/state`` (and, at start, the alert service's ``alerts/active`` answer, for
the state it missed) and keeps the sign at ``WZ_SIGN_HOST:WZ_SIGN_PORT`` showing its
``sign_text``: words filled into the face's lines (``WZ_SIGN_LINES`` x ``WZ_SIGN_CHARS``,
pages as needed), put on with :class:`~wz_drivers.dms.DmsClient`. Only the newest state
counts: states that arrive while the sign is being talked to are skipped for the last.

The sign is a separate process's business on purpose: a sign that does not answer delays
nothing but this driver. It tries again every ``WZ_SIGN_RETRY_S``, reads back what the sign
shows every ``WZ_SIGN_CHECK_S`` (a sign restarted by its own controller comes back blank and
is set again), and reports the link in its status (``devices["dynamic-message-sign"]``:
reachable or not, why, what the sign said it shows, how long since it answered). A sign it
cannot reach makes its state ``degraded``; the gateway shows the sign's ``device_status``
as ``error`` in the WZDx device feed.
"""

from __future__ import annotations

import logging
import time
from typing import Annotated

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from wz_drivers.dms import DmsClient, SignError, SignSettings
from wz_drivers.ntcip1203 import multi_to_text, text_to_multi
from wz_shared.messages import SIGN_DEVICE, ActiveAlerts, DeviceLink, RoadsideDeviceState
from wz_shared.service import NodeApp, ServiceRuntime
from wz_shared.settings import ServiceSettings

SERVICE = "device-driver"
log = logging.getLogger("wz_drivers.device_driver")


class DeviceDriverSettings(ServiceSettings):
    """``WZ_SIGN_*``: where the sign is and how big its face is."""

    model_config = SettingsConfigDict(env_prefix="WZ_SIGN_", extra="ignore")

    host: Annotated[str, Field(min_length=1, max_length=253)]
    port: Annotated[int, Field(ge=1, le=65535)] = 161
    read_community: Annotated[str, Field(min_length=1, max_length=64)] = "public"
    write_community: Annotated[str, Field(min_length=1, max_length=64)] = "administrator"
    #: A portable changeable message sign: 3 lines of 8 characters (NCHRP/MUTCD PCMS).
    lines: Annotated[int, Field(ge=1, le=16)] = 3
    chars: Annotated[int, Field(ge=1, le=64)] = 8
    timeout_s: Annotated[float, Field(gt=0.0, le=10.0)] = 0.4
    retries: Annotated[int, Field(ge=0, le=5)] = 1
    #: After a failed exchange, the next try [s].
    retry_s: Annotated[float, Field(gt=0.0, le=600.0)] = 1.0
    #: What the sign shows is read back this often [s].
    check_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 5.0


class SignDriver:
    """Keeps one sign showing the wanted message; no bus (the node feeds it)."""

    def __init__(self, settings: DeviceDriverSettings, client: DmsClient) -> None:
        self.settings = settings
        self.client = client
        self.address = client.settings.address
        self.wanted: str | None = None  # MULTI; None: nothing asked yet
        self.shown: str | None = None  # what the sign last said it shows
        self.reachable: bool | None = None
        self.detail = "not contacted yet"
        self.answered_at: float | None = None
        self._next_try = 0.0
        self._next_check = 0.0

    def want(self, text: str) -> None:
        """Ask for ``text`` (the alert service's sign text; empty: blank)."""
        chars, lines = self.settings.chars, self.settings.lines
        try:
            multi = text_to_multi(text, chars, lines)
        except ValueError as exc:  # a word wider than the face: shown cut, and said
            log.error("%r on a %d x %d sign: %s; words cut to %d", text, lines, chars, exc, chars)
            multi = text_to_multi(" ".join(w[:chars] for w in text.split()), chars, lines)
        if multi != self.wanted:
            self.wanted = multi
            self._next_try = 0.0

    def step(self, now: float) -> bool:
        """Talk to the sign if there is something to do now; True if it changed the face."""
        if now < self._next_try:
            return False
        try:
            if self.wanted is not None and self.shown != self.wanted:
                started = time.monotonic()
                self.shown = self.client.show(self.wanted)
                self._answered(now, f"showing {multi_to_text(self.shown)!r}")
                log.info(
                    "sign %s shows %r (%.0f ms)",
                    self.address,
                    self.shown,
                    1000 * (time.monotonic() - started),
                )
                return True
            if now >= self._next_check:
                self.shown = self.client.showing()
                self._answered(now, f"showing {multi_to_text(self.shown)!r}")
                if self.wanted is not None and self.shown != self.wanted:
                    log.warning(
                        "sign %s shows %r, not %r: setting it again",
                        self.address,
                        self.shown,
                        self.wanted,
                    )
                    return self.step(now)
        except SignError as exc:
            if exc.answered:  # it answers but refuses: asking again soon will not help
                log.error("sign %s refused %r: %s", self.address, self.wanted, exc)
                self._answered(now, f"refused {multi_to_text(self.wanted or '')!r}: {exc}")
                self._next_try = now + self.settings.check_s
                return False
            if self.reachable is not False:
                log.error("sign %s: %s", self.address, exc)
            self.reachable = False
            self.detail = str(exc)
            self.shown = None  # unknown: set it again once it answers
            self._next_try = now + self.settings.retry_s
        return False

    def _answered(self, now: float, detail: str) -> None:
        if self.reachable is False:
            log.warning("sign %s answers again", self.address)
        self.reachable = True
        self.detail = detail
        self.answered_at = now
        self._next_check = now + self.settings.check_s

    def link(self, now: float) -> DeviceLink:
        """The sign as the status reports it."""
        return DeviceLink(
            address=self.address,
            reachable=self.reachable,
            detail=self.detail[:512],
            shows=None if self.shown is None else multi_to_text(self.shown)[:512],
            answer_age_s=None if self.answered_at is None else max(0.0, now - self.answered_at),
        )


def run(runtime: ServiceRuntime, settings: DeviceDriverSettings) -> int:
    """Drive the sign until ``runtime.stop``; the number of changes of its face."""
    bus = runtime.bus
    states = bus.subscribe(bus.keys.devices_state, RoadsideDeviceState, capacity=64)
    client = DmsClient(
        SignSettings(
            host=settings.host,
            port=settings.port,
            read_community=settings.read_community,
            write_community=settings.write_community,
            timeout_s=settings.timeout_s,
            retries=settings.retries,
        )
    )
    driver = SignDriver(settings, client)
    changes = 0
    next_ask = 0.0
    try:
        while not runtime.stop.is_set():
            newest = states.recv(0.05)
            for later in states.drain():
                newest = later
            now = time.monotonic()
            if newest is None and driver.wanted is None and now >= next_ask:
                # Joined late (or before the alert service): ask it what the sign shows now.
                joined = bus.query(bus.keys.alerts_active, ActiveAlerts, timeout_s=0.5)
                newest = joined[0].devices if joined else None
                next_ask = now + settings.check_s
            if newest is not None:
                driver.want(newest.sign_text)
            now = time.monotonic()
            changes += driver.step(now)
            runtime.devices = {SIGN_DEVICE: driver.link(now)}
            runtime.beat(processed=newest is not None)
    finally:
        client.close()
    return changes


def main() -> None:
    node = NodeApp(SERVICE, DeviceDriverSettings)
    node.load_site()
    changes = node.serve(lambda runtime: run(runtime, node.settings), sim_clock=False)
    log.info("stopped after %d changes of the sign", changes)


if __name__ == "__main__":
    main()

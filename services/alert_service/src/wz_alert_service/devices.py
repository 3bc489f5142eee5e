"""Roadside devices driven by the active alerts: a flashing beacon and a message sign.

:func:`roadside_devices` turns the engine's open episodes into what the devices at the sign
station show; the gateway puts it in its WZDx device feed (a flashing beacon and a dynamic
message sign field device). Pure: no I/O, no clock.

- **Beacon**: flashes while any speeding, aggressive-approach, late-merge, short-TTC, queue or
  queue-approach episode is open upstream of the end of the activity area (drivers still approaching the
  work space). Hard braking and intrusion do not light it: they are reported, but a beacon
  upstream tells approaching drivers nothing about them.
- **Sign**: one message, by priority: a queue, then a late merge (``MERGE RIGHT NOW`` or
  ``LEFT``), then speeding, aggressive approach or a short TTC (``SLOW DOWN``); blank
  otherwise (a driver approaching the queue too fast before the queue's own episode has
  opened: ``SLOW DOWN``). A queue reads ``STOPPED TRAFFIC AHEAD`` while a lane's queue is stopped
  (:mod:`wz_alert_service.queues`), otherwise ``SLOW TRAFFIC 0.3 MI``: the distance from the
  sign to the queue's back in tenths of a mile (``SLOW TRAFFIC AHEAD`` when the back is within
  0.05 mi of the sign, behind it, or beyond the sensors' reach, where no distance is measured,
  unless the site's upstream point sensors bound it: then the distance is to their upstream
  bound, the nearest the back may stand, :mod:`wz_alert_service.queues`).

:class:`SignHold` keeps the sign from flickering: a new message for the same cause (the
queue's distance, slow against stopped) replaces the shown one only once it has held
``message_hold_s``; a new cause, a queue turning to stopped, and a blank sign come at once
(the episodes have their own hold and clear times).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from wz_alert_service.engine import ActiveAlert
from wz_alert_service.zone import ZoneGeometry
from wz_shared.messages import AlertType, QueueCondition, QueueState, RoadsideDeviceState

METERS_PER_MILE = 1609.344
#: ``source_id`` of the device states, unless the caller names another.
DEFAULT_SOURCE_ID = "alert-service"

#: Alert types that light the beacon, in the sign's priority order.
SIGN_PRIORITY: tuple[AlertType, ...] = (
    AlertType.QUEUE,
    AlertType.QUEUE_APPROACH,
    AlertType.LATE_MERGE,
    AlertType.SPEEDING,
    AlertType.AGGRESSIVE_APPROACH,
    AlertType.SHORT_TTC,
)


STOPPED_TEXT = "STOPPED TRAFFIC AHEAD"


def queue_sign_text(
    tail_station_m: float | None,
    sign_station_m: float,
    *,
    stopped: bool = False,
) -> str:
    """The queue's message: ``STOPPED TRAFFIC AHEAD``, or ``SLOW TRAFFIC x.x MI``.

    ``x.x = floor(10 (s_tail - s_sign) / 1609.344 + 0.5) / 10`` (tenths of a mile, halves
    rounded up); ``SLOW TRAFFIC AHEAD`` when that rounds below 0.1 mi (the tail is within
    0.05 mi of the sign, or behind it) or when the tail is not measured (None: beyond the
    sensors' reach).
    """
    if stopped:
        return STOPPED_TEXT
    if tail_station_m is None:
        return "SLOW TRAFFIC AHEAD"
    tenths = math.floor(10.0 * (tail_station_m - sign_station_m) / METERS_PER_MILE + 0.5)
    if tenths < 1:
        return "SLOW TRAFFIC AHEAD"
    return f"SLOW TRAFFIC {tenths / 10:.1f} MI"


def roadside_devices(
    active: Iterable[ActiveAlert],
    zone: ZoneGeometry,
    stamp: float,
    *,
    source_id: str = DEFAULT_SOURCE_ID,
    queue_state: QueueState | None = None,
) -> RoadsideDeviceState:
    """The beacon and the sign for the open episodes.

    Parameters
    ----------
    active : iterable of ActiveAlert
        The engine's open episodes (:meth:`~wz_alert_service.engine.AlertEngine.active`).
    zone : ZoneGeometry
        The sign's station, the merge direction, the end of the activity area.
    stamp : float
        Capture time these states hold for [s].
    source_id : str
        Who decided them (the service's name).
    queue_state : QueueState, optional
        The lanes' queue now: a stopped lane makes a queue's message ``STOPPED TRAFFIC
        AHEAD``; a back beyond the sensors' reach gives no distance (but to the point
        sensors' upstream bound, where they bound it). Without it, the queue
        alert's tail and ``SLOW TRAFFIC``.

    Returns
    -------
    RoadsideDeviceState
        The bus message (:class:`wz_shared.messages.RoadsideDeviceState`) of the zone's site.
    """
    site = zone.site.site_id
    upstream = [
        alert
        for alert in active
        if alert.alert_type in SIGN_PRIORITY and alert.finding.station_m < zone.approach_end_m
    ]
    if not upstream:
        return RoadsideDeviceState(
            site=site, source_id=source_id, stamp=stamp, beacon_on=False, sign_text=""
        )
    cause = min((alert.alert_type for alert in upstream), key=SIGN_PRIORITY.index)
    if cause is AlertType.QUEUE:
        tail_m = min(a.finding.station_m for a in upstream if a.alert_type is AlertType.QUEUE)
        stopped = False
        measured: float | None = tail_m
        if queue_state is not None:
            stopped = queue_state.condition is QueueCondition.STOPPED
            beyond = [lane for lane in queue_state.lanes if lane.back_beyond_reach]
            if beyond:
                # The point sensors' upstream bound: the nearest the back may stand to the
                # sign (None: no sensor bounds it).
                bounds = [lane.back_upstream_bound_m for lane in beyond]
                measured = None if None in bounds else min(b for b in bounds if b is not None)
        return RoadsideDeviceState(
            site=site,
            source_id=source_id,
            stamp=stamp,
            beacon_on=True,
            sign_text=queue_sign_text(measured, zone.sign_station_m, stopped=stopped),
            cause=cause,
            queue_tail_station_m=tail_m,
        )
    text = f"MERGE {zone.merge_direction} NOW" if cause is AlertType.LATE_MERGE else "SLOW DOWN"
    return RoadsideDeviceState(
        site=site, source_id=source_id, stamp=stamp, beacon_on=True, sign_text=text, cause=cause
    )


class SignHold:
    """Holds the sign's message against flicker (see the module's notes).

    Parameters
    ----------
    hold_s : float
        How long a new message for the same cause must hold before it is shown [s]
        (``alerts.devices.message_hold_s``).
    """

    def __init__(self, hold_s: float) -> None:
        self.hold_s = hold_s
        self.shown: RoadsideDeviceState | None = None
        self._candidate: RoadsideDeviceState | None = None
        self._candidate_since_s = 0.0

    @staticmethod
    def _at_once(wanted: RoadsideDeviceState, shown: RoadsideDeviceState) -> bool:
        """A new cause, a blank, a queue turning to stopped, or the same text: no waiting."""
        return (
            wanted.cause is None
            or wanted.cause != shown.cause
            or wanted.sign_text == shown.sign_text
            or (wanted.sign_text == STOPPED_TEXT and shown.sign_text != STOPPED_TEXT)
        )

    def apply(self, wanted: RoadsideDeviceState) -> RoadsideDeviceState:
        """What the devices show, given what the open episodes want at ``wanted.stamp``."""
        if self.shown is None or self._at_once(wanted, self.shown):
            self.shown, self._candidate = wanted, None
            return wanted
        if self._candidate is None or self._candidate.sign_text != wanted.sign_text:
            self._candidate, self._candidate_since_s = wanted, wanted.stamp
        if wanted.stamp - self._candidate_since_s >= self.hold_s:
            self.shown, self._candidate = wanted, None
            return wanted
        return self.shown.model_copy(update={"stamp": wanted.stamp})

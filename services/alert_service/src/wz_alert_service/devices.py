"""Roadside devices driven by the active alerts: a flashing beacon and a message sign.

:func:`roadside_devices` turns the engine's open episodes into what the devices at the sign
station show; the gateway puts it in its WZDx device feed (a flashing beacon and a dynamic
message sign field device). Pure: no I/O, no clock.

- **Beacon**: flashes while any speeding, aggressive-approach, late-merge, short-TTC or queue
  episode is open upstream of the end of the activity area (drivers still approaching the
  work space). Hard braking and intrusion do not light it: they are reported, but a beacon
  upstream tells approaching drivers nothing about them.
- **Sign**: one message, by priority: a queue (``QUEUE AHEAD 0.3 MI``, the distance from the
  sign to the queue's tail in tenths of a mile; ``QUEUE AHEAD`` when the tail is within
  0.05 mi of the sign or behind it), then a late merge (``MERGE RIGHT NOW`` or ``LEFT``), then
  speeding, aggressive approach or a short TTC (``SLOW DOWN``); blank otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from wz_alert_service.engine import ActiveAlert
from wz_alert_service.zone import ZoneGeometry
from wz_shared.messages import AlertType, RoadsideDeviceState

METERS_PER_MILE = 1609.344
#: ``source_id`` of the device states, unless the caller names another.
DEFAULT_SOURCE_ID = "alert-service"

#: Alert types that light the beacon, in the sign's priority order.
SIGN_PRIORITY: tuple[AlertType, ...] = (
    AlertType.QUEUE,
    AlertType.LATE_MERGE,
    AlertType.SPEEDING,
    AlertType.AGGRESSIVE_APPROACH,
    AlertType.SHORT_TTC,
)


def queue_sign_text(tail_station_m: float, sign_station_m: float) -> str:
    """``QUEUE AHEAD x.x MI``: the distance from the sign to the queue's tail.

    ``x.x = floor(10 (s_tail - s_sign) / 1609.344 + 0.5) / 10`` (tenths of a mile, halves
    rounded up); ``QUEUE AHEAD`` alone when that rounds below 0.1 mi (the tail is within
    0.05 mi of the sign, or behind it).
    """
    tenths = math.floor(10.0 * (tail_station_m - sign_station_m) / METERS_PER_MILE + 0.5)
    if tenths < 1:
        return "QUEUE AHEAD"
    return f"QUEUE AHEAD {tenths / 10:.1f} MI"


def roadside_devices(
    active: Iterable[ActiveAlert],
    zone: ZoneGeometry,
    stamp: float,
    *,
    source_id: str = DEFAULT_SOURCE_ID,
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
        return RoadsideDeviceState(
            site=site,
            source_id=source_id,
            stamp=stamp,
            beacon_on=True,
            sign_text=queue_sign_text(tail_m, zone.sign_station_m),
            cause=cause,
            queue_tail_station_m=tail_m,
        )
    text = f"MERGE {zone.merge_direction} NOW" if cause is AlertType.LATE_MERGE else "SLOW DOWN"
    return RoadsideDeviceState(
        site=site, source_id=source_id, stamp=stamp, beacon_on=True, sign_text=text, cause=cause
    )

"""Alert service: speed-and-risk rules on fused tracks in the road frame (pure core).

The pure core, no I/O:

* :mod:`wz_alert_service.zone`: the work zone as the rules see it (approach, taper, zone
  limit, the closed lane's band), read once from the site file;
* :mod:`wz_alert_service.rules`: one small function per rule (speeding, aggressive approach,
  hard braking, late merge, short time to collision, queue, intrusion), each with its enter
  and exit thresholds;
* :mod:`wz_alert_service.engine`: :class:`AlertEngine`, fed track batches, keeping one
  episode per (track, rule) with hold, clear and cool-down times; its events become
  :class:`wz_shared.messages.Alert` messages;
* :mod:`wz_alert_service.devices`: the flashing beacon and message sign the open episodes
  call for (a :class:`wz_shared.messages.RoadsideDeviceState`).

The node, :mod:`wz_alert_service.node` (``python -m wz_alert_service.node``), is the only
module that touches the bus: track batches in, alerts and device states out.

The thresholds, with units and the reasons for their defaults, are
:class:`wz_shared.site.AlertRules`, the ``alerts:`` section of the site file.
"""

from wz_alert_service.devices import roadside_devices
from wz_alert_service.engine import ActiveAlert, AlertEngine, AlertEvent, EngineCounters
from wz_alert_service.rules import Finding
from wz_alert_service.zone import ZoneGeometry
from wz_shared.messages import RoadsideDeviceState

__all__ = [
    "ActiveAlert",
    "AlertEngine",
    "AlertEvent",
    "EngineCounters",
    "Finding",
    "RoadsideDeviceState",
    "ZoneGeometry",
    "roadside_devices",
]

"""Alert episodes that outlive the alert service's process: saved, recovered, continued or
cleared.

Every open episode's newest published event (its start or last update) is written to a state
file (``WZ_ALERT_STATE_FILE``; atomic: a temporary file renamed over the old one) whenever an
event is published. A service that starts again, after a crash, a ``kill -9`` or an upgrade,
reads that file and hands the episodes to an :class:`EpisodeRecovery`, which sits between its
new engine and the bus:

- when the new engine opens an episode of the same type on the same track (or, for the
  site-wide queue, of the same type), it is the recovered episode going on: no second
  ``start``; the new engine's events go out under the recovered ``episode_id`` (an ``update``
  in place of the start, only if the severity changed), and its clear clears it;
- a recovered episode that the new engine has not opened again within its rule's
  ``hold_s + clear_s`` (+ 1 s for the rules' speed histories) of stream time is cleared with
  one ``clear``: the condition would have needed ``hold_s`` to be found again, and an episode
  whose condition fails for ``clear_s`` ends anyway;
- a new run (the stamps went back: a simulation or replay started again) clears them all.

So a consumer sees exactly one ``clear`` per episode, or its continuation, never a second
``start`` for the same vehicle.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Sequence
from pathlib import Path

from pydantic import ValidationError

from wz_shared.messages import Alert, AlertType
from wz_shared.site import Site

log = logging.getLogger(__name__)

#: Added to each rule's hold and clear times: the rules' speed histories need about a second
#: of samples before they can find the condition again [s].
HISTORY_S = 1.0
EpisodeKey = tuple[AlertType, int | None]


def _key(alert: Alert) -> EpisodeKey:
    return (alert.alert_type, alert.track_id)


def _sequence(alert: Alert) -> int:
    """The sequence number at the end of an ``alert_id`` (``<episode>-<n>``), else 0."""
    tail = alert.alert_id.rsplit("-", 1)[-1]
    return int(tail) if tail.isdigit() else 0


def load_open_episodes(path: Path) -> list[Alert]:
    """The open episodes saved in ``path``; none when it is missing or unreadable (logged)."""
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
        alerts = [Alert.model_validate(item) for item in raw["open_episodes"]]
    except FileNotFoundError:
        return []
    except (OSError, ValueError, KeyError, TypeError, ValidationError) as exc:
        log.warning("cannot read the open episodes in %s (%s): starting without them", path, exc)
        return []
    return [a for a in alerts if a.episode_id is not None and a.phase != "clear"]


def save_open_episodes(path: Path, alerts: Sequence[Alert]) -> None:
    """Write the open episodes' newest events to ``path`` atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    body = {"open_episodes": [a.model_dump(mode="json") for a in alerts]}
    with tmp.open("w", encoding="utf-8") as out:
        json.dump(body, out)
        out.flush()
        os.fsync(out.fileno())
    os.replace(tmp, path)


def clear_event(alert: Alert, stamp: float, why: str, sequence: int | None = None) -> Alert:
    """The clear that ends ``alert``'s episode (its newest event): the next event id of the
    episode (``sequence``, or one past ``alert``'s), stamped no earlier than ``alert``."""
    if sequence is None:
        sequence = _sequence(alert) + 1
    return alert.model_copy(
        update={
            "alert_id": f"{alert.episode_id}-{sequence}",
            "phase": "clear",
            "stamp": max(stamp, alert.stamp),
            "description": f"{alert.description} (cleared: {why})"[:500],
        }
    )


class EpisodeRecovery:
    """Recovered episodes, matched to the new engine's (see the module).

    Parameters
    ----------
    site : Site
        Its ``alerts:`` rules give each type's hold and clear times.
    recovered : sequence of Alert
        The newest published event of each episode open when the last process stopped.
    """

    def __init__(self, site: Site, recovered: Sequence[Alert]) -> None:
        self.site = site
        self.waiting: dict[EpisodeKey, Alert] = {_key(a): a for a in recovered}
        #: New engine's episode id -> the recovered episode it continues (its newest event).
        self.continued: dict[str, Alert] = {}
        self._next: dict[str, int] = {
            str(a.episode_id): _sequence(a) + 1 for a in recovered if a.episode_id
        }
        self._first_stamp: float | None = None
        if recovered:
            log.info(
                "recovered %d open episode(s): %s",
                len(recovered),
                ", ".join(str(a.episode_id) for a in recovered),
            )

    @property
    def active(self) -> bool:
        return bool(self.waiting or self.continued)

    def _grace_s(self, alert_type: AlertType) -> float:
        rule = getattr(self.site.alerts, alert_type.value)
        return float(rule.hold_s + rule.clear_s) + HISTORY_S

    def _next_alert_id(self, recovered: Alert) -> str:
        """The recovered episode's next event id (``<episode>-<n>``, counting on)."""
        episode = str(recovered.episode_id)
        sequence = self._next[episode]
        self._next[episode] = sequence + 1
        return f"{episode}-{sequence}"

    def _as(self, alert: Alert, recovered: Alert, phase: str) -> Alert:
        return alert.model_copy(
            update={
                "episode_id": recovered.episode_id,
                "alert_id": self._next_alert_id(recovered),
                "phase": phase,
                "onset_stamp": recovered.onset_stamp,
            }
        )

    def _cleared(self, recovered: Alert, stamp: float, why: str) -> Alert:
        episode = str(recovered.episode_id)
        sequence = self._next[episode]
        self._next[episode] = sequence + 1
        return clear_event(recovered, stamp, why, sequence)

    def rewrite(self, alerts: list[Alert], stamp: float) -> list[Alert]:
        """The engine's events for the batch at ``stamp``, with the recovered episodes
        continued (their ids), and the clears of those whose grace ran out."""
        if self._first_stamp is None:
            self._first_stamp = stamp
        out: list[Alert] = []
        for alert in alerts:
            engine_episode = str(alert.episode_id)
            if alert.phase == "start" and _key(alert) in self.waiting:
                recovered = self.waiting.pop(_key(alert))
                self.continued[engine_episode] = recovered
                log.info(
                    "episode %s goes on after the restart (as the engine's %s)",
                    recovered.episode_id,
                    engine_episode,
                )
                if alert.severity != recovered.severity:
                    out.append(self._as(alert, recovered, "update"))
                continue
            recovered_for = self.continued.get(engine_episode)
            if recovered_for is None:
                out.append(alert)
                continue
            out.append(self._as(alert, recovered_for, alert.phase))
            if alert.phase == "clear":
                del self.continued[engine_episode]
        for key, recovered in list(self.waiting.items()):
            if stamp - self._first_stamp >= self._grace_s(key[0]):
                del self.waiting[key]
                out.append(self._cleared(recovered, stamp, "not found again after a restart"))
        return out

    def clear_all(self, stamp: float, why: str) -> list[Alert]:
        """Clear every recovered episode, waiting or continued (a new run)."""
        out = [self._cleared(a, stamp, why) for a in self.waiting.values()]
        out += [self._cleared(a, stamp, why) for a in self.continued.values()]
        self.waiting.clear()
        self.continued.clear()
        return out

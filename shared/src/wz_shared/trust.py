"""Who may say what on the bus: the services' roles, the routers' access control, and the
check every consumer makes of a message's source.

Outside the development stack on loopback, every session authenticates to its router with its
own certificate (mutual TLS, a certificate per service signed by the site's CA: ``wz
credentials``), and the router's access control allows each one only what its role says
(:data:`ROLES`). A session whose certificate names no role, or that has none, can do nothing:
the router drops its declarations and its samples before any consumer sees them. So a laptop
plugged into the trailer's switch cannot put an alert, a detection or a track batch on the
bus.

Roles (a certificate's common name is the role's name)::

    simulator        raw sensor data, truth, the point sensors' readings; serves the site
                     description
    drivers          raw sensor data, the radar-camera unit's object lists (detections), the
                     upstream point speed sensors' readings
    lidar-detector   detections
    camera-detector  detections
    fusion-tracker   tracks; serves the newest batch
    alert-service    alerts, the roadside devices' state; serves the open episodes
    gateway          reads (and its own status)
    device-driver    reads the devices' state (and its own status: the sign's and beacon's links)
    operator         reads: wz status, wz tap, wz record on the box
    regional-router  reads: the trailer router's uplink, seen from the trailer

Each service also publishes its own status and liveliness token
(``wz/<site>/status/<name>``), no other service's.

The routers' rules are seen from the router: *ingress* is what a session sends to the router
(its samples, its declarations, its replies), *egress* what the router sends to it.

A certificate is bound to its site. Its common name is ``<role>@<site>#<generation>``
(:func:`identity`): ``alert-service@us75-lincoln#1``. One DOT's trailers share one CA, so
the name is what tells them apart: a trailer router's access control (made per site by ``wz
credentials make``, :func:`edge_access_control`) names its own site's identities and its own
site's keys only (``wz/us75-lincoln/...``), and the regional router's names each trailer's
router with its site's keys (:func:`regional_access_control`). A key taken from one trailer
on a roadside then does nothing at any other trailer, nor for any other site at the regional
router. The *generation* revokes: re-making a site's credentials (``wz credentials make``
again, or ``wz credentials revoke``) moves it on, and the access controls then name the new
generation only, so the certificates of the old one (a stolen box's) are refused once the
routers run the new rules.

Key expressions with a verbatim chunk (``@adv``: the history caches and liveliness tokens of
Zenoh's advanced publishers and subscribers) are not matched by ``*`` or ``**``, so each key
with a history is allowed with its ``/@adv/**`` too.

A consumer also checks what it takes (:func:`site_problem`, :func:`source_problem`): a message
whose ``site`` is not its key's, a track batch whose
``source_id`` is not the tracker's, an alert not from the alert service, a detection batch
whose ``source_id`` is not the sensor its key names, is refused and counted
(``wrong_source``), not used.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wz_shared.keys import ROOT

#: Every message type a Zenoh 1.x access-control rule can name.
ALL_MESSAGES = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
)
#: What a session sends to take data: its interest (subscriptions, queries) ...
INTEREST = ("declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query")
#: ... and what it sends to give data.
DATA = ("put", "delete", "reply", "liveliness_token", "declare_queryable")

#: The roles of the services (as in ``wz up``'s stack), by the site-relative keys each may put
#: samples on and answer queries on.
TRACKER = "fusion-tracker"
ALERT_SERVICE = "alert-service"


@dataclass(frozen=True)
class Role:
    """What one service may give to the bus, besides its own status.

    Attributes
    ----------
    name : str
        The service's name: its status key's last chunk and its certificate's common name.
    publishes : tuple of str
        Site-relative key expressions it puts samples on (``alerts/*``).
    serves : tuple of str
        Site-relative key expressions it answers queries on.
    """

    name: str
    publishes: tuple[str, ...] = ()
    serves: tuple[str, ...] = ()


RAW = ("raw/lidar/*", "raw/camera/*", "raw/radar/*")
ROLES: Mapping[str, Role] = {
    role.name: role
    for role in (
        # upstream point speed sensors (points/*): SUMO's loops in simulation, a driver's
        # side-fire radars on the road
        Role("simulator", publishes=(*RAW, "truth/vehicles", "points/*"), serves=("config/site",)),
        Role("drivers", publishes=(*RAW, "detections/*", "points/*")),
        # each detector publishes its sensors' self-calibration (pose correction, clock)
        Role("lidar-detector", publishes=("detections/*", "calibration/*")),
        Role("camera-detector", publishes=("detections/*", "calibration/*")),
        Role(TRACKER, publishes=("tracks",), serves=("tracks/latest",)),
        Role(
            ALERT_SERVICE,
            publishes=("alerts/*", "devices/state", "queue"),
            serves=("alerts/active",),
        ),
        Role("gateway"),
        # drives the message sign and the beacon's relay from the devices' state; puts only its
        # status
        Role("device-driver"),
    )
}
#: Sessions that only read: the operator's tools on the box, and the regional router's link
#: seen from the trailer's router.
READERS = ("operator", "regional-router")
#: The regional router's own identity (it is no site's): what a trailer router lets read.
REGIONAL_ROUTER = "regional-router"
#: A site's identity that is no service's: the trailer's router.
ROUTER_ROLE = "router"

_IDENTITY = re.compile(r"^(?P<role>[a-z0-9-]+)@(?P<site>[^@#/*?$]+)#(?P<generation>[1-9][0-9]*)$")


def identity(role: str, site: str, generation: int) -> str:
    """The common name of ``role``'s certificate at ``site``: ``<role>@<site>#<generation>``."""
    if generation < 1:
        raise ValueError(f"a credentials generation counts from 1, not {generation}")
    return f"{role}@{site}#{generation}"


def parse_identity(common_name: str) -> tuple[str, str, int] | None:
    """``(role, site, generation)`` of a site's certificate name; None for another name (the
    regional router's, the centre's)."""
    match = _IDENTITY.match(common_name)
    if match is None:
        return None
    return match["role"], match["site"], int(match["generation"])


def _site_keys(site: str, suffixes: Iterable[str]) -> list[str]:
    keys: list[str] = []
    for suffix in suffixes:
        key = f"{ROOT}/{site}/{suffix}"
        keys += [key, f"{key}/@adv/**"]
    return keys


def _rule(
    rule_id: str, flows: list[str], messages: Iterable[str], keys: list[str]
) -> dict[str, Any]:
    return {
        "id": rule_id,
        "permission": "allow",
        "flows": flows,
        "messages": list(messages),
        "key_exprs": keys,
    }


def _deny_but(
    rules: list[dict[str, Any]], subjects: list[dict[str, Any]], policies: list[dict[str, Any]]
) -> dict[str, Any]:
    """An ``access_control`` block: whatever no policy allows is denied."""
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def _everything(site: str) -> list[str]:
    # Wildcards stop at verbatim chunks: the advanced publishers' and subscribers' keys apart.
    # Any site: wz/** (which a subscription on wz/** is included in; wz/*/** is not).
    prefix = ROOT if site == "*" else f"{ROOT}/{site}"
    return [f"{prefix}/**", f"{prefix}/**/@adv/**"]


def edge_access_control(site: str, generation: int) -> dict[str, Any]:
    """A trailer router's ``access_control`` block: each role's certificate of ``site`` (its
    current ``generation``) may give what :data:`ROLES` says on ``site``'s keys and take
    ``site``'s keys; the site's operator and the regional router only take; nobody else, and
    no other site's certificate, anything.
    """
    rules = [
        # Interest in any site (a rule's keys must include what is declared, and the centre's
        # subscriptions name every site at once: wz/*/alerts/*); what comes back is only ever
        # this site's, the one site anybody may put here.
        _rule("take: interest", ["ingress"], INTEREST, _everything("*")),
        # Egress: others' interest, relayed, may name any site too; data only this site's.
        _rule("take: data", ["egress"], DATA, _everything(site)),
        _rule("take: others' interest", ["egress"], INTEREST, _everything("*")),
    ]
    policies: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    for role in ROLES.values():
        give = f"{role.name}: gives"
        keys = _site_keys(site, (*role.publishes, *role.serves, f"status/{role.name}"))
        rules.append(_rule(give, ["ingress"], DATA, keys))
        subjects.append(
            {"id": role.name, "cert_common_names": [identity(role.name, site, generation)]}
        )
        policies.append(
            {
                "id": role.name,
                "rules": [give, "take: interest", "take: data", "take: others' interest"],
                "subjects": [role.name],
            }
        )
    # The operator also reads the router's admin space (which sessions and links are up).
    rules.append(
        _rule("operator: admin space", ["ingress", "egress"], ("query", "reply"), ["@/**"])
    )
    for reader in READERS:
        name = REGIONAL_ROUTER if reader == REGIONAL_ROUTER else identity(reader, site, generation)
        subjects.append({"id": reader, "cert_common_names": [name]})
        extra = ["operator: admin space"] if reader == "operator" else []
        policies.append(
            {
                "id": reader,
                "rules": ["take: interest", "take: data", "take: others' interest", *extra],
                "subjects": [reader],
            }
        )
    return _deny_but(rules, subjects, policies)


def deny_all() -> dict[str, Any]:
    """An ``access_control`` block that lets nobody do anything: a trailer router's config as
    shipped, until ``wz router --tls-dir`` puts the site's own in its place (fail closed)."""
    return _deny_but([], [], [])


def trailer_name(site: str, generation: int) -> str:
    """The common name of a trailer router's certificate, as the regional router knows it."""
    return identity(ROUTER_ROLE, site, generation)


#: The central side's reading sessions at the regional router.
CENTRAL_READERS = ("central-gateway", "operator")


def regional_access_control(sites: Mapping[str, int]) -> dict[str, Any]:
    """The regional router's ``access_control`` block: each trailer (``sites``: site -> its
    credentials' generation) gives only its own site's keys (samples, tokens, replies) and
    gets only the centre's interest, no samples; the central gateway and operator take every
    site's. A site's services' certificates are named nowhere here: they only reach their
    own trailer's router.
    """
    rules = [
        _rule("central: interest", ["ingress"], INTEREST, _everything("*")),
        _rule("central: data", ["egress"], ALL_MESSAGES, _everything("*")),
        # the central gateway's own status and liveliness
        _rule("central: status", ["ingress"], DATA, _site_keys("*", ["status/central-gateway"])),
        # The centre's interest reaches every trailer: its subscriptions and queries name
        # every site at once (wz/*/alerts/*), and a rule's keys must include what is declared.
        # Interest only: nothing the region puts reaches a trailer.
        _rule("trailers: are asked", ["egress"], INTEREST, _everything("*")),
    ]
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for reader in CENTRAL_READERS:
        subjects.append({"id": reader, "cert_common_names": [reader]})
        policies.append(
            {
                "id": reader,
                "rules": ["central: interest", "central: data", "central: status"],
                "subjects": [reader],
            }
        )
    for site in sorted(sites):
        name = trailer_name(site, sites[site])
        key = f"trailer {site}"
        rules.append(_rule(f"{key}: gives", ["ingress"], ALL_MESSAGES, _everything(site)))
        subjects.append({"id": key, "cert_common_names": [name]})
        policies.append(
            {"id": key, "rules": [f"{key}: gives", "trailers: are asked"], "subjects": [key]}
        )
    return _deny_but(rules, subjects, policies)


# --- TLS ------------------------------------------------------------------------------------

#: The files of one identity's credentials folder (``wz credentials``).
CA_FILE, CERT_FILE, KEY_FILE = "ca.pem", "cert.pem", "key.pem"
#: A router's generated access control, in its credentials folder (the regional router's).
ACL_FILE = "access-control.json"


def tls_config(folder: Path) -> dict[str, Any]:
    """The ``transport/link/tls`` block of a session whose credentials are in ``folder``:
    trust only the site's CA, show its own certificate when it connects and when it is
    connected to (mutual TLS), close a link whose certificate expires."""
    ca, cert, key = (str(folder / name) for name in (CA_FILE, CERT_FILE, KEY_FILE))
    return {
        "root_ca_certificate": ca,
        "enable_mtls": True,
        "connect_certificate": cert,
        "connect_private_key": key,
        "listen_certificate": cert,
        "listen_private_key": key,
        "verify_name_on_connect": True,
        "close_link_on_expiration": True,
    }


# --- consumers ------------------------------------------------------------------------------


@functools.lru_cache(maxsize=4096)
def expected_source(key: str) -> str | None:
    """The ``source_id`` a message on the concrete ``key`` must carry, or None when any may.

    Raw data, detections, calibrations and point readings carry their sensor's id, the key's
    last chunk; tracks the tracker's name; alerts, the devices' state and the queue the alert
    service's; a status its service's.
    """
    parts = str(key).split("/")
    if len(parts) < 3 or parts[0] != ROOT:
        return None
    rest = parts[2:]
    if rest[0] in ("raw", "detections", "calibration", "points", "status") and len(rest) >= 2:
        return rest[-1]
    if rest == ["tracks"]:
        return TRACKER
    if (rest[0] == "alerts" and len(rest) == 2) or rest in (["devices", "state"], ["queue"]):
        return ALERT_SERVICE
    return None


def site_problem(key: str, site: str) -> str | None:
    """Why a message naming ``site`` is not to be taken from ``key``, or None (a key outside
    ``wz/<site>/...`` names no site)."""
    parts = str(key).split("/", 2)
    if len(parts) < 3 or parts[0] != ROOT or parts[1] == site:
        return None
    return f"{key} is site {parts[1]}'s, not {site}'s"


def source_problem(key: str, source_id: str) -> str | None:
    """Why a message from ``source_id`` is not to be taken from ``key``, or None."""
    expected = expected_source(key)
    if expected is None or source_id == expected:
        return None
    return f"{key} carries {expected}'s messages, not {source_id}'s"

"""``wz credentials``: the certificates a site's bus runs on.

One folder holds a DOT's credentials, all signed by one certificate authority (CA) made on
first use::

    DIR/ca/ca.pem, ca-key.pem         the CA (keep ca-key.pem offline; nothing mounts it)
    DIR/<site>/generation              the site's credentials generation (1, 2, ...)
    DIR/<site>/router/                 the trailer's router: CN router@<site>#<generation>,
                                       for the names the services and the regional router
                                       reach it by, and its access-control.json (the site's)
    DIR/<site>/<service>/              one per role of wz_shared.trust.ROLES:
                                       CN <role>@<site>#<generation>
    DIR/<site>/operator/               wz status, wz tap, wz record on the box (reads only)
    DIR/regional/router/               the regional router (CN regional-router) and its
                                       access-control.json, naming every site in DIR
    DIR/regional/central-gateway/, DIR/regional/operator/

Each identity's folder holds ``ca.pem`` (the CA's certificate), ``cert.pem`` and ``key.pem``
(its own, EC P-256): what ``WZ_BUS_TLS_DIR`` and ``wz router --tls-dir`` take, and what the
containers mount at ``/etc/wz/tls``. A container sees its own folder only, so a compromised
detector cannot speak as the alert service. Keys are written mode 0600, owned by ``--uid``
(the images' user, 65534) when given.

A certificate names its site (:func:`wz_shared.trust.identity`), and each router's access
control names the identities it takes (:mod:`wz_shared.trust`): another site's certificate,
though signed by the same CA, is refused.

**Rotation.** Making a site again (``make`` on a site that exists) re-keys it: a new
generation, every certificate of the site issued anew, its router's access control and the
regional router's rewritten to name the new generation only. The other sites keep working.
Install the new folders on the trailer and restart its containers, and restart the regional
router: from then on the old generation's certificates are refused everywhere.

**Revocation** (a trailer stolen, its keys taken): ``wz credentials revoke DIR --site SITE``
moves the site to a new generation and deletes its identities without issuing new ones, and
rewrites the regional access control without the site. Restart the regional router: nothing
of the stolen box's reaches the region or any other site. ``make`` re-provisions the site
later (a generation newer still).
"""

from __future__ import annotations

import datetime
import ipaddress
import json
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from wz_cli.common import CliError
from wz_shared.keys import Keys
from wz_shared.trust import (
    ACL_FILE,
    CA_FILE,
    CENTRAL_READERS,
    CERT_FILE,
    KEY_FILE,
    REGIONAL_ROUTER,
    ROLES,
    ROUTER_ROLE,
    edge_access_control,
    identity,
    regional_access_control,
)

#: Names a trailer router is reached by: the compose service, and the box itself.
ROUTER_NAMES = ("router", "localhost", "127.0.0.1")
REGIONAL = "regional"
CA_DAYS = 3650
#: A site's credentials generation, in its folder.
GENERATION_FILE = "generation"
#: Left in a site's folder by ``revoke``: no identity of it is valid until ``make`` again.
REVOKED_FILE = "revoked"


@dataclass(frozen=True)
class Authority:
    """The CA: its certificate and key."""

    cert: x509.Certificate
    key: ec.EllipticCurvePrivateKey


def _write(path: Path, data: bytes, *, secret: bool, uid: int | None) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600 if secret else 0o644)
    with os.fdopen(fd, "wb") as out:
        out.write(data)
    if uid is not None:
        os.chown(tmp, uid, -1)
    os.replace(tmp, path)


def _pem_key(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _name(common_name: str) -> x509.Name:
    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "wz work-zone bus"),
            x509.NameAttribute(NameOID.COMMON_NAME, common_name),
        ]
    )


def load_or_make_ca(folder: Path, *, uid: int | None = None) -> Authority:
    """The CA in ``folder/ca``, made (valid :data:`CA_DAYS`) when there is none."""
    cert_path, key_path = folder / "ca" / "ca.pem", folder / "ca" / "ca-key.pem"
    if cert_path.exists() and key_path.exists():
        try:
            cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
            key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
        except ValueError as exc:
            raise CliError(f"{folder / 'ca'} holds no usable CA: {exc}", 1) from exc
        if not isinstance(key, ec.EllipticCurvePrivateKey):
            raise CliError(f"{key_path} is not an EC key", 1)
        return Authority(cert, key)
    key = ec.generate_private_key(ec.SECP256R1())
    now = datetime.datetime.now(datetime.UTC)
    name = _name("wz bus CA")
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=CA_DAYS))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=False,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .sign(key, hashes.SHA256())
    )
    _write(key_path, _pem_key(key), secret=True, uid=None)  # the CA key stays root's
    _write(cert_path, cert.public_bytes(serialization.Encoding.PEM), secret=False, uid=uid)
    return Authority(cert, key)


def _san(names: Iterable[str]) -> list[x509.GeneralName]:
    out: list[x509.GeneralName] = []
    for name in names:
        try:
            out.append(x509.IPAddress(ipaddress.ip_address(name)))
        except ValueError:
            out.append(x509.DNSName(name))
    return out


def issue(
    ca: Authority,
    folder: Path,
    common_name: str,
    *,
    names: Sequence[str] = (),
    days: int,
    uid: int | None = None,
) -> None:
    """Write ``folder/{ca,cert,key}.pem``: a certificate for ``common_name`` signed by ``ca``,
    for client and server use (a router is both), valid for ``names`` (DNS names or IP
    addresses a peer connects to it by)."""
    key = ec.generate_private_key(ec.SECP256R1())
    now = datetime.datetime.now(datetime.UTC)
    builder = (
        x509.CertificateBuilder()
        .subject_name(_name(common_name))
        .issuer_name(ca.cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(x509.SubjectAlternativeName(_san(names or [common_name])), critical=False)
    )
    cert = builder.sign(ca.key, hashes.SHA256())
    _write(folder / KEY_FILE, _pem_key(key), secret=True, uid=uid)
    _write(folder / CERT_FILE, cert.public_bytes(serialization.Encoding.PEM), secret=False, uid=uid)
    _write(
        folder / CA_FILE, ca.cert.public_bytes(serialization.Encoding.PEM), secret=False, uid=uid
    )


def generation(folder: Path, site: str) -> int:
    """The site's current credentials generation; 0 when it has none yet."""
    path = folder / site / GENERATION_FILE
    if not path.is_file():
        # Made before generations were recorded: its certificates name no site (refused).
        return 1 if (folder / site / ROUTER_ROLE).is_dir() else 0
    try:
        return int(path.read_text(encoding="utf-8").strip())
    except ValueError as exc:
        raise CliError(f"{path} holds no generation number", 1) from exc


def _checked_site(site: str) -> None:
    try:
        Keys(site)
    except ValueError as exc:
        raise CliError(str(exc)) from exc


def _identities(site_dir: Path) -> list[Path]:
    return [path for path in sorted(site_dir.iterdir()) if (path / CERT_FILE).is_file()]


def make_site(
    folder: Path,
    site: str,
    *,
    router_names: Sequence[str] = (),
    days: int = 400,
    uid: int | None = None,
) -> list[Path]:
    """Every identity of one site (see the module), at a new generation; the folders written.

    A site that exists is re-keyed (rotation): its old generation is named by no access
    control any more.
    """
    _checked_site(site)
    ca = load_or_make_ca(folder, uid=uid)
    site_dir = folder / site
    current = generation(folder, site) + 1
    if site_dir.is_dir():
        for old in _identities(site_dir):
            _remove_identity(old)
    _write(site_dir / GENERATION_FILE, f"{current}\n".encode(), secret=False, uid=None)
    (site_dir / REVOKED_FILE).unlink(missing_ok=True)
    written = []
    router = site_dir / ROUTER_ROLE
    issue(
        ca,
        router,
        identity(ROUTER_ROLE, site, current),
        names=[*ROUTER_NAMES, *router_names],
        days=days,
        uid=uid,
    )
    acl = edge_access_control(site, current)
    _write(router / ACL_FILE, (json.dumps(acl, indent=2) + "\n").encode(), secret=False, uid=uid)
    written.append(router)
    for name in [*ROLES, "operator"]:
        # Its name for TLS (a DNS name, as before the site was in the common name): the role.
        issue(ca, site_dir / name, identity(name, site, current), names=[name], days=days, uid=uid)
        written.append(site_dir / name)
    if (folder / REGIONAL / "router").exists():
        write_regional_acl(folder, uid=uid)
    return written


def _remove_identity(path: Path) -> None:
    for name in (KEY_FILE, CERT_FILE, CA_FILE, ACL_FILE):
        (path / name).unlink(missing_ok=True)
    if not any(path.iterdir()):
        path.rmdir()


def revoke_site(folder: Path, site: str) -> list[Path]:
    """Revoke every identity of ``site`` (see the module); the folders removed."""
    _checked_site(site)
    site_dir = folder / site
    if not site_dir.is_dir():
        raise CliError(f"{folder} has no credentials of site {site}", 1)
    current = generation(folder, site) + 1
    removed = _identities(site_dir)
    for path in removed:
        _remove_identity(path)
    _write(site_dir / GENERATION_FILE, f"{current}\n".encode(), secret=False, uid=None)
    _write(site_dir / REVOKED_FILE, b"", secret=False, uid=None)
    if (folder / REGIONAL / "router").exists():
        write_regional_acl(folder)
    return removed


def sites_in(folder: Path) -> dict[str, int]:
    """The sites with valid credentials in ``folder``, each with its generation."""
    return {
        path.name: generation(folder, path.name)
        for path in sorted(folder.iterdir())
        if path.is_dir()
        and path.name not in ("ca", REGIONAL)
        and (path / ROUTER_ROLE / CERT_FILE).is_file()
        and not (path / REVOKED_FILE).exists()
    }


def write_regional_acl(folder: Path, *, uid: int | None = None) -> Path:
    path = folder / REGIONAL / "router" / ACL_FILE
    acl = regional_access_control(sites_in(folder))
    _write(path, (json.dumps(acl, indent=2) + "\n").encode(), secret=False, uid=uid)
    return path


def make_regional(
    folder: Path, *, names: Sequence[str], days: int = 400, uid: int | None = None
) -> list[Path]:
    """The regional router (reached by ``names``), the central gateway and operator, and the
    regional router's access control for the sites in ``folder``; the folders written."""
    if not names:
        raise CliError("name the regional router's host names or addresses (--name)")
    ca = load_or_make_ca(folder, uid=uid)
    regional = folder / REGIONAL
    issue(ca, regional / "router", REGIONAL_ROUTER, names=list(names), days=days, uid=uid)
    for name in CENTRAL_READERS:
        issue(ca, regional / name, name, days=days, uid=uid)
    write_regional_acl(folder, uid=uid)
    return [regional / "router", *(regional / name for name in CENTRAL_READERS)]


def describe(folder: Path) -> list[str]:
    """One line per certificate under ``folder``: its path, common name and expiry."""
    lines = []
    for path in sorted(folder.rglob(CERT_FILE)):
        cert = x509.load_pem_x509_certificate(path.read_bytes())
        cn = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value
        expires = cert.not_valid_after_utc.date().isoformat()
        lines.append(f"{path.parent.relative_to(folder)}  CN={cn!s}  expires {expires}")
    return lines

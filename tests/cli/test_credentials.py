"""`wz credentials`: a site's certificates for the bus (the CLI as a process, real files)."""

from __future__ import annotations

import json
import stat
from pathlib import Path

from cryptography import x509
from cryptography.x509.oid import NameOID

from tests.cli.procs import run_wz
from wz_shared.trust import ROLES, edge_access_control, regional_access_control


def _cn(path: Path) -> str:
    cert = x509.load_pem_x509_certificate(path.read_bytes())
    return str(cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value)


def test_make_writes_one_identity_per_role_signed_by_one_ca(tmp_path: Path) -> None:
    result = run_wz("credentials", "make", str(tmp_path), "--site", "i80-omaha")
    assert result.returncode == 0, result.stderr
    site = tmp_path / "i80-omaha"
    names = sorted(p.name for p in site.iterdir() if p.is_dir())
    assert names == sorted([*ROLES, "operator", "router"])
    assert (site / "generation").read_text().strip() == "1"
    ca = x509.load_pem_x509_certificate((tmp_path / "ca" / "ca.pem").read_bytes())
    for name in names:
        folder = site / name
        assert _cn(folder / "cert.pem") == f"{name}@i80-omaha#1"
        cert = x509.load_pem_x509_certificate((folder / "cert.pem").read_bytes())
        cert.verify_directly_issued_by(ca)  # raises if another CA signed it
        assert stat.S_IMODE((folder / "key.pem").stat().st_mode) == 0o600
        assert (folder / "ca.pem").read_bytes() == (tmp_path / "ca" / "ca.pem").read_bytes()
        assert f"i80-omaha/{name}  CN=" in result.stdout
    router = x509.load_pem_x509_certificate((site / "router" / "cert.pem").read_bytes())
    names_in_cert = router.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert {"router", "localhost"} <= set(names_in_cert.get_values_for_type(x509.DNSName))
    # A second site and the centre: the same CA; the centre's rules name both sites.
    assert run_wz("credentials", "make", str(tmp_path), "--site", "us75-lincoln").returncode == 0
    result = run_wz("credentials", "regional", str(tmp_path), "--name", "regional.example.org")
    assert result.returncode == 0, result.stderr
    acl = json.loads((tmp_path / "regional" / "router" / "access-control.json").read_text())
    assert acl == regional_access_control({"i80-omaha": 1, "us75-lincoln": 1})
    edge = json.loads((site / "router" / "access-control.json").read_text())
    assert edge == edge_access_control("i80-omaha", 1)
    again = x509.load_pem_x509_certificate((tmp_path / "ca" / "ca.pem").read_bytes())
    assert again == ca


def test_bad_arguments_get_a_clear_error(tmp_path: Path) -> None:
    result = run_wz("credentials", "make", str(tmp_path), "--site", "Bad/Site")
    assert result.returncode == 2 and "cannot be part of a key expression" in result.stderr
    result = run_wz("credentials", "make", str(tmp_path))
    assert result.returncode == 2 and "--site" in result.stderr
    result = run_wz("credentials", "regional", str(tmp_path))
    assert result.returncode == 2 and "--name" in result.stderr
    result = run_wz("credentials", "list", str(tmp_path / "none"))
    assert result.returncode == 1 and "no credentials" in result.stderr


def test_make_again_rotates_and_revoke_withdraws_a_site(tmp_path: Path) -> None:
    """Rotation: a new generation, every certificate anew, the access controls name it only.
    Revocation: the site's identities gone, the regional rules without it; make again later
    re-provisions it at a newer generation still. The other site is untouched throughout."""
    for site in ("i80-omaha", "us75-lincoln"):
        assert run_wz("credentials", "make", str(tmp_path), "--site", site).returncode == 0
    assert run_wz("credentials", "regional", str(tmp_path), "--name", "r.example").returncode == 0
    regional_acl = tmp_path / "regional" / "router" / "access-control.json"
    omaha = tmp_path / "i80-omaha"
    lincoln_cert = (tmp_path / "us75-lincoln" / "gateway" / "cert.pem").read_bytes()
    old_key = (omaha / "gateway" / "key.pem").read_bytes()

    rotated = run_wz("credentials", "make", str(tmp_path), "--site", "i80-omaha")
    assert rotated.returncode == 0, rotated.stderr
    assert _cn(omaha / "gateway" / "cert.pem") == "gateway@i80-omaha#2"
    assert (omaha / "gateway" / "key.pem").read_bytes() != old_key
    edge = json.loads((omaha / "router" / "access-control.json").read_text())
    assert edge == edge_access_control("i80-omaha", 2)
    assert json.loads(regional_acl.read_text()) == regional_access_control(
        {"i80-omaha": 2, "us75-lincoln": 1}
    )
    assert (tmp_path / "us75-lincoln" / "gateway" / "cert.pem").read_bytes() == lincoln_cert

    revoked = run_wz("credentials", "revoke", str(tmp_path), "--site", "i80-omaha")
    assert revoked.returncode == 0, revoked.stderr
    assert "revoked" in revoked.stdout and not (omaha / "gateway").exists()
    assert not list(omaha.glob("*/cert.pem"))
    assert json.loads(regional_acl.read_text()) == regional_access_control({"us75-lincoln": 1})
    again = run_wz("credentials", "make", str(tmp_path), "--site", "i80-omaha")
    assert again.returncode == 0
    assert _cn(omaha / "router" / "cert.pem") == "router@i80-omaha#4"
    assert json.loads(regional_acl.read_text()) == regional_access_control(
        {"i80-omaha": 4, "us75-lincoln": 1}
    )
    missing = run_wz("credentials", "revoke", str(tmp_path), "--site", "nowhere")
    assert missing.returncode == 1 and "no credentials of site nowhere" in missing.stderr
    no_site = run_wz("credentials", "revoke", str(tmp_path))
    assert no_site.returncode == 2 and "--site" in no_site.stderr

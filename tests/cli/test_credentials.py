"""`wz credentials`: a site's certificates for the bus (the CLI as a process, real files)."""

from __future__ import annotations

import json
import stat
from pathlib import Path

from cryptography import x509
from cryptography.x509.oid import NameOID

from tests.cli.procs import run_wz
from wz_shared.trust import ROLES, regional_access_control


def _cn(path: Path) -> str:
    cert = x509.load_pem_x509_certificate(path.read_bytes())
    return str(cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value)


def test_make_writes_one_identity_per_role_signed_by_one_ca(tmp_path: Path) -> None:
    result = run_wz("credentials", "make", str(tmp_path), "--site", "i80-omaha")
    assert result.returncode == 0, result.stderr
    site = tmp_path / "i80-omaha"
    names = sorted(p.name for p in site.iterdir())
    assert names == sorted([*ROLES, "operator", "router"])
    ca = x509.load_pem_x509_certificate((tmp_path / "ca" / "ca.pem").read_bytes())
    for name in names:
        folder = site / name
        assert _cn(folder / "cert.pem") == ("trailer-i80-omaha" if name == "router" else name)
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
    assert acl == regional_access_control(["i80-omaha", "us75-lincoln"])
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

"""The page's HTTPS certificate and pairing token, made on first use and kept for the next sessions.

A headset's browser only offers WebXR to a secure context, so the page is served over HTTPS with a
self-signed certificate: the browser asks once to accept it ("Advanced", "Proceed"), and keeps the
exception as long as the certificate stays the same. It names localhost, 127.0.0.1 and the addresses
the server is reached at; a new address (another network) makes a new one. The token, which a page
served beyond this machine must carry in its URL, is kept beside it, so that a bookmarked URL keeps working.
"""

from __future__ import annotations

import datetime as _dt
import ipaddress
import os
import secrets
from dataclasses import dataclass
from pathlib import Path

CERT, KEY, TOKEN = "cert.pem", "key.pem", "pairing-token"
VALID_DAYS = 825
RENEW_DAYS = 30  # a certificate this close to expiring is made again


def default_dir() -> Path:
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "teleprev" / "webxr"


@dataclass(frozen=True)
class Credentials:
    cert: Path
    key: Path
    token: str


def ensure(folder: Path, addresses: list[str]) -> Credentials:
    """The certificate (covering `addresses` besides localhost and 127.0.0.1) and token in `folder`,
    made when missing, expiring, or not covering an address."""
    folder.mkdir(parents=True, exist_ok=True)
    cert, key, token_file = folder / CERT, folder / KEY, folder / TOKEN
    wanted = {"127.0.0.1", *addresses}
    if not (cert.exists() and key.exists() and _covers(cert, wanted)):
        _make(cert, key, sorted(wanted))
    if not token_file.exists() or not token_file.read_text().strip():
        _write_private(token_file, secrets.token_urlsafe(16).encode())
    return Credentials(cert, key, token_file.read_text().strip())


def _covers(cert: Path, addresses: set[str]) -> bool:
    from cryptography import x509

    try:
        c = x509.load_pem_x509_certificate(cert.read_bytes())
        names = c.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except (ValueError, x509.ExtensionNotFound):
        return False
    have = {str(a) for a in names.get_values_for_type(x509.IPAddress)}
    left = c.not_valid_after_utc - _dt.datetime.now(_dt.UTC)
    return addresses <= have and left > _dt.timedelta(days=RENEW_DAYS)


def _make(cert: Path, key: Path, addresses: list[str]) -> None:
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    private = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "teleprev webxr")])
    now = _dt.datetime.now(_dt.UTC)
    alt = [x509.DNSName("localhost"), *(x509.IPAddress(ipaddress.ip_address(a)) for a in addresses)]
    built = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(private.public_key())
             .serial_number(x509.random_serial_number()).not_valid_before(now - _dt.timedelta(minutes=5))
             .not_valid_after(now + _dt.timedelta(days=VALID_DAYS))
             .add_extension(x509.SubjectAlternativeName(alt), critical=False)
             .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
             .sign(private, hashes.SHA256()))
    _write_private(key, private.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                              serialization.NoEncryption()))
    cert.write_bytes(built.public_bytes(serialization.Encoding.PEM))


def _write_private(path: Path, data: bytes) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(data)

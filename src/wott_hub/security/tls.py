"""TLS for the hub's HTTP and WebSocket ports, and a self-signed pair for a lab.

``server_context`` is the standard library's ``ssl`` (TLS 1.2 at least) loaded with the
configured PEM certificate chain and key; both tornado servers take it as
``ssl_options``, so the same pair serves ``https://`` and ``wss://``.
``write_selfsigned`` (``wott-hub tls selfsigned --out DIR``) makes a lab pair with the
``cryptography`` package, imported only then.
"""

from __future__ import annotations

import datetime
import ipaddress
import os
import ssl
from collections.abc import Sequence
from pathlib import Path

from wott_hub.errors import ConfigError

__all__ = ["server_context", "write_selfsigned"]


def server_context(cert: str | Path, key: str | Path) -> ssl.SSLContext:
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    try:
        ctx.load_cert_chain(str(cert), str(key))
    except FileNotFoundError as e:  # ssl names no file: say which of the two is missing
        missing = [str(p) for p in (cert, key) if not Path(p).is_file()] or [f"{cert} or {key}"]
        raise ConfigError(f"[security]: cannot read {' and '.join(missing)}: {e.strerror}") from None
    except (ssl.SSLError, OSError) as e:
        raise ConfigError(f"[security] cert/key: {cert}, {key}: not a matching PEM certificate and "
                          f"key ({e})") from None
    return ctx


def write_selfsigned(out: str | Path, hosts: Sequence[str] = ("localhost", "127.0.0.1"),
                     days: int = 365) -> tuple[Path, Path]:
    """``cert.pem`` and ``key.pem`` (mode 0600) in ``out``, valid for ``hosts`` (names or IPs).

    The certificate is its own CA: clients trust it by pointing at ``cert.pem``
    (``curl --cacert``, ``NODE_EXTRA_CA_CERTS``, ``ssl.create_default_context(cafile=...)``).
    """
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import NameOID
    except ImportError:
        raise ConfigError("the 'cryptography' package is not installed: make the pair with openssl "
                          "instead (docs/security.md, 'A certificate for a lab')") from None

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, hosts[0] if hosts else "wott-hub")])
    sans: list[x509.GeneralName] = []
    for h in hosts:
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            sans.append(x509.DNSName(h))
    now = datetime.datetime.now(datetime.UTC)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=days))
            .add_extension(x509.SubjectAlternativeName(sans), critical=False)
            .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
            .sign(key, hashes.SHA256()))
    cert_path, key_path = out / "cert.pem", out / "key.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    fd = os.open(key_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                  serialization.NoEncryption()))
    return cert_path, key_path

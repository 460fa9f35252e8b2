"""`sme secure init DIR`: a private CA and one certificate per role for the locked-down bus.

Files (keys are written 0600, the directory 0700):

- ``ca.pem`` the CA certificate every role trusts; ``ca.key`` its key (only needed to issue more
  certificates: keep it off the machines that run the bus).
- ``agent.pem``/``agent.key`` (CN ``sme-agent``): the daemon's router and the agent as a client.
- ``world.pem``/``world.key`` (CN ``sme-world``): `sme world`, `sme replay`.
- ``tool.pem``/``tool.key`` (CN ``sme-tool``): `sme record`, `watch`, `status`, `view` (read-only).
- ``perturb.pem``/``perturb.key`` (CN ``sme-perturb``): `sme perturb`.
"""

from __future__ import annotations

import argparse
import datetime as dt
import ipaddress
import os
import sys
from pathlib import Path

from sensorimotor.protocol.security import CA_FILE, CA_KEY_FILE, CREDENTIALS, common_name

README = """\
Credentials of a locked-down sme bus (made by `sme secure init`). Pass this directory as --secure DIR.

  ca.pem            CA certificate, trusted by every role
  ca.key            CA private key: only to issue new certificates; move it somewhere safe
  agent.pem/.key    CN sme-agent   `sme agent` (router, server certificate; also as a client), `sme demo`
  world.pem/.key    CN sme-world   `sme world`, `sme replay`
  tool.pem/.key     CN sme-tool    `sme record`, `sme watch`, `sme status`, `sme view` (read-only)
  perturb.pem/.key  CN sme-perturb `sme perturb` (may only put controls)

The agent certificate is valid for: {names}
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register `sme secure init`."""
    p = sub.add_parser(
        "secure",
        help="credentials for a locked-down bus (mutual TLS + access control)",
        description="Make the private CA and per-role certificates that `--secure DIR` uses.",
    )
    ssub = p.add_subparsers(dest="secure_command", metavar="SUBCOMMAND")
    init = ssub.add_parser(
        "init",
        help="create DIR with a private CA and one key + certificate per role",
        description="Create DIR (mode 0700) with a private CA (ca.pem, ca.key) and, per role, a key "
        "(0600) and a certificate signed by the CA with its own common name: agent.pem/.key "
        "(sme-agent: the daemon's router and the agent as a client), world.pem/.key (sme-world: sme "
        "world, sme replay), tool.pem/.key (sme-tool: record, watch, status, view; read-only), "
        "perturb.pem/.key (sme-perturb: sme perturb). Then pass --secure DIR to every command.",
    )
    init.add_argument("dir", metavar="DIR", help="directory to create")
    init.add_argument("--force", action="store_true", help="overwrite existing credentials in DIR")
    init.add_argument(
        "--host",
        action="append",
        default=None,
        metavar="NAME_OR_IP",
        help="extra DNS name or IP address the agent is reached at, repeatable (always: localhost, "
        "127.0.0.1, ::1); clients check the agent's certificate against the host they connect to",
    )
    init.add_argument("--days", type=int, default=825, help="validity of the certificates in days (default 825)")
    init.set_defaults(func=init_main)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def _names(hosts: list[str]) -> list[str]:
    out = ["localhost", "127.0.0.1", "::1"]
    for h in hosts:
        if h and h not in out:
            out.append(h)
    return out


def _write(path: Path, data: bytes, mode: int) -> None:
    """Write `data` to `path` created with `mode` (never briefly world-readable)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode)
    try:
        os.write(fd, data)
    finally:
        os.close(fd)
    os.chmod(path, mode)


def init(
    directory: str | os.PathLike[str], force: bool = False, hosts: list[str] | None = None, days: int = 825
) -> list[Path]:
    """Create the CA and the per-role credentials in `directory`; the paths written.

    Parameters
    ----------
    directory : path
        Created (0700) if missing.
    force : bool
        Overwrite existing files; otherwise FileExistsError if any credential file exists.
    hosts : list of str
        Extra DNS names / IP addresses for the agent's server certificate.
    days : int
        Validity of every certificate.
    """
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    if days < 1:
        raise ValueError("--days must be >= 1")
    d = Path(directory)
    files = [CA_FILE, CA_KEY_FILE] + [f"{r}.{ext}" for r in CREDENTIALS for ext in ("pem", "key")]
    existing = [f for f in files if (d / f).exists()]
    if existing and not force:
        raise FileExistsError(f"{d} already holds {', '.join(existing)}; pass --force to overwrite")
    d.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(d, 0o700)
    now = dt.datetime.now(dt.UTC) - dt.timedelta(minutes=5)
    until = now + dt.timedelta(days=days)

    def pem_key(k: ec.EllipticCurvePrivateKey) -> bytes:
        return k.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
        )

    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "sme private CA")])
    ca_cert = (
        x509.CertificateBuilder()
        .subject_name(ca_name)
        .issuer_name(ca_name)
        .public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now)
        .not_valid_after(until)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(False, False, False, False, False, True, True, False, False), critical=True
        )  # key_cert_sign, crl_sign
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()), critical=False)
        .sign(ca_key, hashes.SHA256())
    )
    written = [d / CA_FILE, d / CA_KEY_FILE]
    _write(d / CA_KEY_FILE, pem_key(ca_key), 0o600)
    _write(d / CA_FILE, ca_cert.public_bytes(serialization.Encoding.PEM), 0o644)
    names = _names(hosts or [])
    for role in CREDENTIALS:
        key = ec.generate_private_key(ec.SECP256R1())
        cn = common_name(role)
        if role == "agent":
            sans: list[x509.GeneralName] = []
            for n in names:
                try:
                    sans.append(x509.IPAddress(ipaddress.ip_address(n)))
                except ValueError:
                    sans.append(x509.DNSName(n))
            usage = [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
        else:
            sans = [x509.DNSName(cn)]
            usage = [ExtendedKeyUsageOID.CLIENT_AUTH]
        cert = (
            x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)]))
            .issuer_name(ca_name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now)
            .not_valid_after(until)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(
                x509.KeyUsage(True, False, False, False, False, False, False, False, False), critical=True
            )  # digital_signature
            .add_extension(x509.ExtendedKeyUsage(usage), critical=False)
            .add_extension(x509.SubjectAlternativeName(sans), critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
            .sign(ca_key, hashes.SHA256())
        )
        _write(d / f"{role}.key", pem_key(key), 0o600)
        _write(d / f"{role}.pem", cert.public_bytes(serialization.Encoding.PEM), 0o644)
        written += [d / f"{role}.pem", d / f"{role}.key"]
    _write(d / "README.txt", README.format(names=", ".join(names)).encode(), 0o644)
    return written


def init_main(args: argparse.Namespace) -> int:
    """`sme secure init DIR`: exit 0, or 2 when DIR already holds credentials (without --force)."""
    try:
        init(args.dir, args.force, args.host, args.days)
    except (FileExistsError, ValueError) as e:
        print(f"sme secure init: {e}", file=sys.stderr)
        return 2
    print(
        f"sme secure init: wrote a private CA and the agent, world, tool and perturb credentials to {args.dir} "
        f"(see {os.path.join(args.dir, 'README.txt')}); pass --secure {args.dir} to every command"
    )
    return 0

"""A range's keys: its certificate authority, one key and certificate per role, and each role's Zenoh config.

:func:`make_range_keys` writes a directory (``rapt-plan bus-keys``)::

    ca.pem, ca.key            the range CA (keep ca.key off the vehicle: it signs new roles)
    <role>.pem, <role>.key    the role's certificate (common name = the role) and private key
    <role>.json5              the role's complete Zenoh config: mutual TLS, scouting off

The bridge's config listens on the hub endpoint as a peer and carries the access-control
rules of :func:`bridge.access.access_rules`; every other role connects to the hub as a
client. :func:`role_config` checks a role's files (signed by the CA, in date, key matching,
key private) before it loads the config, so a bad file is a one-line error at start rather
than a refused handshake later.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import json
import os
import stat
from collections.abc import Iterable
from pathlib import Path

import zenoh
from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from bridge import keys
from bridge.access import HUB_ROLE, OTHER_ROLES, access_rules
from bridge.session import CONNECT_TIMEOUT_S
from rapt.errors import FileFormatError, InputError, MissingFileError

__all__ = ["ROLES", "DEFAULT_TLS_HUB", "make_range_keys", "role_config", "role_names", "write_certificate"]

#: The kinds of role on a range's bus. Each autonomy is a role of its own, named by its source name.
ROLES = (HUB_ROLE, "autonomy", keys.WATCHDOG_SOURCE, "logger", "operator")
#: The hub endpoint when none is given: the bridge's TLS listener.
DEFAULT_TLS_HUB = "tls/127.0.0.1:7448"
_CA = "ca"
_MAKE = "make them with rapt-plan bus-keys DIR --vehicle NAME"


def _hub_host(hub: str) -> str:
    protocol, _, address = str(hub).partition("/")
    host, _, port = address.rpartition(":")
    host = host.strip("[]")
    if protocol != "tls" or not host or not port.isdigit():
        raise InputError(f"--hub: {hub!r} is not a TLS endpoint like 'tls/127.0.0.1:7448'")
    return host


def _name(value: str, argument: str) -> str:
    try:
        keys.status("v", value)
    except (ValueError, TypeError):
        raise InputError(f"{argument}: {value!r} is not a single key chunk (letters, digits, '_', '.', '-')") from None
    return value


def _write(path: Path, data: bytes, mode: int) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.chmod(path, mode)


def _new_key() -> ec.EllipticCurvePrivateKey:
    return ec.generate_private_key(ec.SECP256R1())


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )


def write_certificate(
    directory: Path,
    name: str,
    ca_cert: x509.Certificate | None,
    ca_key: ec.EllipticCurvePrivateKey | None,
    *,
    not_before: dt.datetime,
    not_after: dt.datetime,
    hosts: Iterable[str] = (),
) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    """Write ``<name>.pem`` and ``<name>.key`` (0600): a CA when ``ca_cert`` is None, else a role it signs.

    A role's certificate names ``hosts`` (IP addresses or DNS names) so a client that checks the
    hub's name accepts it, and serves both as a TLS server and a client.
    """
    key = _new_key()
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    builder = (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(subject if ca_cert is None else ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(not_before)
        .not_valid_after(not_after)
    )
    if ca_cert is None:
        builder = builder.add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True).add_extension(
            x509.KeyUsage(False, False, False, False, False, True, True, False, False), critical=True
        )
        signer = key
    else:
        assert ca_key is not None
        names: list[x509.GeneralName] = []
        for host in dict.fromkeys(hosts):
            try:
                names.append(x509.IPAddress(ipaddress.ip_address(host)))
            except ValueError:
                names.append(x509.DNSName(host))
        builder = (
            builder.add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.KeyUsage(True, False, False, False, False, False, False, False, False), critical=True)
            .add_extension(
                x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]),
                critical=False,
            )
            .add_extension(x509.SubjectAlternativeName(names), critical=False)
        )
        signer = ca_key
    cert = builder.sign(signer, hashes.SHA256())
    _write(directory / f"{name}.pem", cert.public_bytes(serialization.Encoding.PEM), 0o644)
    _write(directory / f"{name}.key", _key_pem(key), 0o600)
    return cert, key


def _tls(directory: Path, role: str, *, listen: bool) -> dict:
    ca, pem, key = (str((directory / f"{n}").resolve()) for n in (f"{_CA}.pem", f"{role}.pem", f"{role}.key"))
    tls = {
        "root_ca_certificate": ca,
        "enable_mtls": True,
        "verify_name_on_connect": True,
        "connect_private_key": key,
        "connect_certificate": pem,
    }
    if listen:
        tls.update(listen_private_key=key, listen_certificate=pem)
    return tls


def _config(directory: Path, role: str, vehicle: str, hub: str, autonomies: list[str]) -> dict:
    hub_role = role == HUB_ROLE
    config: dict = {
        "mode": "peer" if hub_role else "client",
        "listen": {"endpoints": [hub] if hub_role else []},
        "connect": {"endpoints": [] if hub_role else [hub]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"link": {"tls": _tls(directory, role, listen=hub_role)}},
    }
    if hub_role:
        config["access_control"] = access_rules(vehicle, autonomies)
    else:
        config["connect"].update(
            timeout_ms=int(CONNECT_TIMEOUT_S * 1000),
            retry={"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2},
        )
    return config


def make_range_keys(
    directory: str | Path,
    vehicle: str,
    *,
    hub: str = DEFAULT_TLS_HUB,
    autonomies: Iterable[str] = (keys.DEFAULT_ACTIVE,),
    valid_days: int = 365,
    force: bool = False,
) -> Path:
    """Write a range CA and every role's key, certificate and Zenoh config into ``directory``; return it.

    ``autonomies`` names each autonomy (its certificate's common name and its ``command/<name>``
    key). An existing non-empty ``directory`` is refused unless ``force``, which replaces the
    keys, certificates and configs in it.
    """
    vehicle = _name(vehicle, "--vehicle")
    host = _hub_host(hub)
    autonomies = [_name(a, "--autonomy") for a in autonomies]
    if not autonomies:
        raise InputError("--autonomy: name at least one autonomy (default: autonomy)")
    clash = sorted(
        {a for a in autonomies if a in (HUB_ROLE, *OTHER_ROLES, _CA)}
        | {a for a in autonomies if autonomies.count(a) > 1}
    )
    if clash:
        raise InputError(
            f"--autonomy: {clash[0]!r} is named twice or is another role's name; give each autonomy its own name"
        )
    if not isinstance(valid_days, int) or valid_days < 1:
        raise InputError(f"--days: expected a whole number of days >= 1, got {valid_days!r}")
    path = Path(directory)
    if path.exists() and not path.is_dir():
        raise InputError(f"DIR: {str(path)!r} is a file; name a new directory")
    if path.is_dir() and any(path.iterdir()):
        if not force:
            raise InputError(
                f"DIR: {str(path)!r} already exists and is not empty; name a new one or pass --force to replace its keys"
            )
        for old in path.iterdir():
            if old.is_file() and old.suffix in (".pem", ".key", ".json5"):
                old.unlink()
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(path, 0o700)
    now = dt.datetime.now(dt.UTC)
    start, end = now - dt.timedelta(minutes=5), now + dt.timedelta(days=valid_days)
    ca_cert, ca_key = write_certificate(path, _CA, None, None, not_before=start, not_after=end)
    hosts = [host, "127.0.0.1", "localhost"]
    for role in [HUB_ROLE, *autonomies, *OTHER_ROLES]:
        write_certificate(path, role, ca_cert, ca_key, not_before=start, not_after=end, hosts=hosts)
        text = json.dumps(_config(path, role, vehicle, hub, autonomies), indent=2)
        _write(path / f"{role}.json5", (text + "\n").encode(), 0o644)
    return path


def role_names(directory: str | Path) -> list[str]:
    """The roles in ``directory``: each with a config, a certificate and a key."""
    path = Path(directory)
    if not path.is_dir():
        return []
    return sorted(
        p.stem
        for p in path.glob("*.json5")
        if (path / f"{p.stem}.pem").is_file() and (path / f"{p.stem}.key").is_file()
    )


def _load_cert(path: Path) -> x509.Certificate:
    try:
        return x509.load_pem_x509_certificate(path.read_bytes())
    except ValueError:
        raise FileFormatError(f"{path}: not a PEM certificate; {_MAKE}") from None


def role_config(directory: str | Path, role: str) -> zenoh.Config:
    """``role``'s Zenoh config from ``directory``, after checking its files; nothing joins the bus before.

    Raises :class:`~rapt.errors.InputError` (or ``MissingFileError``) naming the file and the fix:
    role not in the directory, certificate not signed by its CA, out of date or not this role's,
    key not matching, key readable by others.
    """
    path = Path(directory)
    if not path.is_dir():
        raise MissingFileError(f"--bus-keys: {str(path)!r} is not a directory; {_MAKE}")
    present = role_names(path)
    config_file = path / f"{role}.json5"
    if role not in present:
        raise InputError(
            f"--bus-role: {str(config_file)!r} not found, {role!r} is not a role in {str(path)!r} "
            f"(roles there: {', '.join(present) or 'none'}); pick one of them or make its keys with rapt-plan bus-keys"
        )
    ca_file, cert_file, key_file = path / f"{_CA}.pem", path / f"{role}.pem", path / f"{role}.key"
    if not ca_file.is_file():
        raise MissingFileError(
            f"{ca_file}: the range CA's certificate is missing; copy it from where the keys were made"
        )
    ca, cert = _load_cert(ca_file), _load_cert(cert_file)
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        raise InputError(
            f"{cert_file}: not signed by this range's CA ({ca_file}); copy {role}.pem and {role}.key from the same bus-keys DIR"
        ) from None
    names = [a.value for a in cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)]
    if names != [role]:
        raise InputError(f"{cert_file}: its common name is {names}, not {role!r}; copy the file made for {role!r}")
    now = dt.datetime.now(dt.UTC)
    if now > cert.not_valid_after_utc:
        raise InputError(
            f"{cert_file}: expired on {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC; make new keys with rapt-plan bus-keys --force"
        )
    if now < cert.not_valid_before_utc:
        raise InputError(
            f"{cert_file}: not valid before {cert.not_valid_before_utc:%Y-%m-%d %H:%M} UTC; check this computer's clock"
        )
    if stat.S_IMODE(key_file.stat().st_mode) & 0o077:
        raise InputError(f"{key_file}: readable by group or others; chmod 600 {key_file}")
    try:
        key = serialization.load_pem_private_key(key_file.read_bytes(), password=None)
    except (ValueError, TypeError):
        raise FileFormatError(
            f"{key_file}: not an unencrypted PEM private key; copy {role}.key from the bus-keys DIR"
        ) from None
    pem = serialization.PublicFormat.SubjectPublicKeyInfo
    if key.public_key().public_bytes(serialization.Encoding.PEM, pem) != cert.public_key().public_bytes(
        serialization.Encoding.PEM, pem
    ):
        raise InputError(f"{key_file}: does not match {cert_file}; copy the pair made together by rapt-plan bus-keys")
    config = zenoh.Config.from_file(str(config_file))
    # the files where they are now (the directory may have been copied to the vehicle since)
    listen = bool(json.loads(config.get_json("listen/endpoints")))
    for field, value in _tls(path, role, listen=listen).items():
        config.insert_json5(f"transport/link/tls/{field}", json.dumps(value))
    return config

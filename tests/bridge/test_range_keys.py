"""A range's keys: what bus-keys writes, and each bad file a one-line error naming it and the fix."""

from __future__ import annotations

import datetime as dt
import json
import shutil
import stat

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from bridge.range_keys import make_range_keys, role_config, role_names
from rapt.errors import InputError, MissingFileError

ROLES = ["autonomy", "bridge", "logger", "operator", "rogue", "watchdog"]


@pytest.fixture(scope="module")
def keydir(tmp_path_factory):
    """One range's keys (with a second autonomy, rogue), made once; tests that spoil files copy it first."""
    return make_range_keys(tmp_path_factory.mktemp("range") / "keys", "uuv1", autonomies=("autonomy", "rogue"))


@pytest.fixture
def spoilable(keydir, tmp_path):
    copy = tmp_path / "keys"
    shutil.copytree(keydir, copy)
    return copy


def _mode(path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def _cert(path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def test_every_role_gets_a_certificate_signed_by_the_range_ca_and_a_private_key(keydir):
    assert role_names(keydir) == ROLES
    assert _mode(keydir) == 0o700 and _mode(keydir / "ca.key") == 0o600
    ca = _cert(keydir / "ca.pem")
    for role in ROLES:
        assert _mode(keydir / f"{role}.key") == 0o600
        cert = _cert(keydir / f"{role}.pem")
        cert.verify_directly_issued_by(ca)  # raises if another key signed it
        assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == role
        hosts = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        assert "localhost" in hosts.get_values_for_type(x509.DNSName)
        assert role_config(keydir, role) is not None  # every check passes on fresh keys


def test_the_bridge_listens_with_the_access_rules_and_the_others_connect_as_clients(keydir):
    for role in ROLES:
        config = json.loads((keydir / f"{role}.json5").read_text())
        tls = config["transport"]["link"]["tls"]
        assert tls["enable_mtls"] is True and tls["root_ca_certificate"].endswith("ca.pem")
        assert config["scouting"]["multicast"]["enabled"] is False
        if role == "bridge":
            assert config["mode"] == "peer" and config["listen"]["endpoints"] == ["tls/127.0.0.1:7448"]
            assert config["access_control"]["default_permission"] == "deny"
        else:
            assert config["mode"] == "client" and config["connect"]["endpoints"] == ["tls/127.0.0.1:7448"]
            assert "access_control" not in config and config["listen"]["endpoints"] == []


def test_a_moved_directory_still_names_its_own_files(keydir, tmp_path):
    moved = tmp_path / "on-the-vehicle"
    shutil.copytree(keydir, moved)
    config = role_config(moved, "autonomy")
    assert json.loads(config.get_json("transport/link/tls/connect_certificate")) == str(moved / "autonomy.pem")


def test_an_existing_directory_is_replaced_only_with_force(keydir, spoilable):
    with pytest.raises(InputError, match=r"^DIR: .*keys' already exists .*--force") as error:
        make_range_keys(spoilable, "uuv1")
    assert "\n" not in str(error.value)
    before = (spoilable / "ca.pem").read_bytes()
    make_range_keys(spoilable, "uuv1", force=True)  # rogue is not named again: its files go
    assert (spoilable / "ca.pem").read_bytes() != before
    assert role_names(spoilable) == ["autonomy", "bridge", "logger", "operator", "watchdog"]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"hub": "tcp/127.0.0.1:7447"}, r"^--hub: 'tcp/127.0.0.1:7447' is not a TLS endpoint"),
        ({"autonomies": ("logger",)}, r"^--autonomy: 'logger' is named twice or is another role's name"),
        ({"autonomies": ("a/b",)}, r"^--autonomy: 'a/b' is not a single key chunk"),
        ({"valid_days": 0}, r"^--days: expected a whole number of days >= 1"),
    ],
)
def test_bad_arguments_are_refused_before_anything_is_written(tmp_path, kwargs, message):
    with pytest.raises(InputError, match=message):
        make_range_keys(tmp_path / "keys", "uuv1", **kwargs)
    assert not (tmp_path / "keys").exists()


def _sign(directory, role, *, days_from_now: tuple[int, int], key=None) -> None:
    """Replace ``role``'s certificate with one the range CA signs for the given validity (days from now)."""
    ca = _cert(directory / "ca.pem")
    ca_key = serialization.load_pem_private_key((directory / "ca.key").read_bytes(), password=None)
    key = key or ec.generate_private_key(ec.SECP256R1())
    now = dt.datetime.now(dt.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, role)]))
        .issuer_name(ca.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now + dt.timedelta(days=days_from_now[0]))
        .not_valid_after(now + dt.timedelta(days=days_from_now[1]))
        .sign(ca_key, hashes.SHA256())
    )
    (directory / f"{role}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption())
    (directory / f"{role}.key").write_bytes(pem)


def _from_another_range(directory, tmp_path):
    other = make_range_keys(tmp_path / "other", "uuv1")
    for suffix in (".pem", ".key"):
        shutil.copy(other / f"autonomy{suffix}", directory / f"autonomy{suffix}")


def _expired(directory, tmp_path):
    _sign(directory, "autonomy", days_from_now=(-30, -1))


def _not_yet_valid(directory, tmp_path):
    _sign(directory, "autonomy", days_from_now=(2, 30))


def _key_of_another_role(directory, tmp_path):
    shutil.copy(directory / "logger.key", directory / "autonomy.key")


def _world_readable(directory, tmp_path):
    (directory / "autonomy.key").chmod(0o644)


def _another_roles_certificate(directory, tmp_path):
    for suffix in (".pem", ".key"):
        shutil.copy(directory / f"rogue{suffix}", directory / f"autonomy{suffix}")


@pytest.mark.parametrize(
    ("spoil", "message"),
    [
        (_from_another_range, r"autonomy.pem: not signed by this range's CA \(.*ca.pem\); copy autonomy.pem and"),
        (_expired, r"autonomy.pem: expired on .* UTC; make new keys with rapt-plan bus-keys --force"),
        (_not_yet_valid, r"autonomy.pem: not valid before .* UTC; check this computer's clock"),
        (_key_of_another_role, r"autonomy.key: does not match .*autonomy.pem; copy the pair"),
        (_world_readable, r"autonomy.key: readable by group or others; chmod 600 .*autonomy.key$"),
        (_another_roles_certificate, r"autonomy.pem: its common name is \['rogue'\], not 'autonomy'"),
    ],
)
def test_each_bad_file_is_a_one_line_error_naming_it_and_the_fix(spoilable, tmp_path, spoil, message):
    spoil(spoilable, tmp_path)
    with pytest.raises(InputError, match=message) as error:
        role_config(spoilable, "autonomy")
    assert "\n" not in str(error.value) and str(spoilable) in str(error.value)
    assert role_config(spoilable, "logger") is not None  # the other roles' files are still good


def test_a_role_not_in_the_directory_lists_the_roles_there(keydir):
    with pytest.raises(InputError, match=r"^--bus-role: '.*/ghost.json5' not found, 'ghost' is not a role") as error:
        role_config(keydir, "ghost")
    assert "(roles there: autonomy, bridge, logger, operator, rogue, watchdog)" in str(error.value)
    with pytest.raises(MissingFileError, match=r"^--bus-keys: '.*nowhere' is not a directory; make them with"):
        role_config(keydir / "nowhere", "autonomy")

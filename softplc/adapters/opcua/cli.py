"""`softplc opcua certs|trust|untrust` and `softplc users add|list|remove`."""

from __future__ import annotations

import argparse
import getpass
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from softplc.config.yamlsource import load_yaml
from softplc.core.roles import ROLE_NAMES
from softplc.util.plurals import plural

if TYPE_CHECKING:  # the rest of softplc.adapters.opcua needs asyncua: each command imports what it uses
    from softplc.adapters.opcua.settings import OpcUaSettings
    from softplc.security.certificates import Pki
    from softplc.security.users import UserStore

EXIT_OK, EXIT_FAILURE = 0, 1


def add_commands(subparsers: Any) -> None:
    """Register `opcua` and `users` with the softplc command line."""
    opcua = subparsers.add_parser(
        "opcua",
        help="OPC UA certificates: list, trust, untrust",
        description="Manage the OPC UA server's PKI: its own certificate, and the client certificates it "
        "trusts. A client whose certificate is not trusted is refused (BadCertificateUntrusted) and its "
        "certificate is kept in the rejected folder, from where `trust` moves it to the trusted one. "
        "Changes take effect at the next connection, without a restart.",
        epilog="Examples: softplc opcua certs | softplc opcua trust 3fa2c91b | softplc opcua trust client.der",
    )
    commands = opcua.add_subparsers(title="subcommands", metavar="SUBCOMMAND")
    certs = commands.add_parser("certs", help="list the server certificate and trusted/rejected client certificates")
    _common(certs)
    certs.set_defaults(func=cmd_certs)
    trust = commands.add_parser("trust", help="trust a client certificate (file, or fingerprint of a rejected one)")
    trust.add_argument("certificate", metavar="CERT|FINGERPRINT", help="a .der/.pem file, or the first 8+ hex digits of a fingerprint")
    _common(trust)
    trust.set_defaults(func=cmd_trust)
    untrust = commands.add_parser("untrust", help="move a trusted certificate back to rejected")
    untrust.add_argument("fingerprint", metavar="FINGERPRINT")
    _common(untrust)
    untrust.set_defaults(func=cmd_untrust)
    opcua.set_defaults(func=lambda args: (opcua.print_help(), EXIT_FAILURE)[1])

    users = subparsers.add_parser(
        "users",
        help="OPC UA users: add, list, remove",
        description="Manage the OPC UA users file: names, roles (viewer: read; operator: also write rw "
        "tags; engineer: also write ro tags) and salted password hashes. Changes take effect at the "
        "next login, without a restart.",
        epilog="Examples: softplc users add alice --role operator | echo secret-pass | softplc users add "
        "bot --role operator --password-stdin | softplc users list | softplc users remove alice",
    )
    user_commands = users.add_subparsers(title="subcommands", metavar="SUBCOMMAND")
    add = user_commands.add_parser("add", help="add a user, or change a user's role/password")
    add.add_argument("name")
    add.add_argument("--role", required=True, choices=ROLE_NAMES)
    add.add_argument("--password-stdin", action="store_true", help="read the password from the first line of stdin")
    add.add_argument("--certificate", metavar="FILE|FINGERPRINT", help="log this user in by client certificate instead of a password")
    _common(add)
    add.set_defaults(func=cmd_users_add)
    listing = user_commands.add_parser("list", help="list users and roles")
    _common(listing)
    listing.set_defaults(func=cmd_users_list)
    remove = user_commands.add_parser("remove", help="remove a user")
    remove.add_argument("name")
    _common(remove)
    remove.set_defaults(func=cmd_users_remove)
    users.set_defaults(func=lambda args: (users.print_help(), EXIT_FAILURE)[1])


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default="tagdb.yaml", help="plant configuration (default tagdb.yaml)")
    parser.add_argument("--state-dir", type=Path, metavar="DIR", help="state directory (default .softplc next to CONFIG)")


def _settings(args: argparse.Namespace) -> tuple[OpcUaSettings, Path]:
    """OPC UA settings and state directory from CONFIG's `servers.opcua` and `runtime` sections.

    Only those sections are read (not the programs), so users and certificates can be managed
    even while the rest of the configuration does not load.
    """
    from softplc.adapters.opcua.settings import OpcUaSettings, SettingsError

    config_path = Path(args.config)
    if not config_path.exists() and args.state_dir is not None:
        return OpcUaSettings(), args.state_dir
    data, _ = load_yaml(config_path)
    data = data if isinstance(data, dict) else {}
    servers = data.get("servers") if isinstance(data.get("servers"), dict) else {}
    runtime = data.get("runtime") if isinstance(data.get("runtime"), dict) else {}
    section = servers.get("opcua") if isinstance(servers.get("opcua"), dict) else {}
    try:
        settings = OpcUaSettings.from_section(section, config_path.parent)
    except (SettingsError, TypeError, ValueError) as error:
        raise SystemExit(f"softplc: {config_path}: servers.opcua: {error}") from None
    state_dir = args.state_dir or config_path.parent / str(runtime.get("state_dir", ".softplc"))
    return settings, state_dir


def _pki(args: argparse.Namespace) -> Pki:
    from softplc.security.certificates import Pki

    settings, state_dir = _settings(args)
    return Pki(settings.pki_path(state_dir))


def _store(args: argparse.Namespace) -> UserStore:
    from softplc.security.users import UserStore

    settings, state_dir = _settings(args)
    return UserStore(settings.users_path(state_dir))  # a broken file raises ConfigError: FILE:LINE:COL


# -- opcua ----------------------------------------------------------------------------------


def cmd_certs(args: argparse.Namespace) -> int:
    from softplc.security.certificates import describe_file
    from softplc.util.console import print_table

    pki = _pki(args)
    own = describe_file(pki.certificate_path) if pki.certificate_path.exists() else None
    print(f"PKI directory: {pki.root}")
    if own is None:
        print("server certificate: none yet (made on the first start with a Basic256Sha256 policy)")
    else:
        print(f"server certificate: {own.path}  {own.subject}  SHA-256 {own.fingerprint}  valid until {own.not_after:%Y-%m-%d}")
    for label, directory in (("trusted", pki.trusted_dir), ("rejected", pki.rejected_dir)):
        infos = pki.list(directory)
        print(f"\n{label} client certificates ({len(infos)}):")
        if infos:
            rows = [[i.fingerprint[:16], i.subject, f"{i.not_after:%Y-%m-%d}", i.path.name] for i in infos]
            print_table(rows, ("fingerprint", "subject", "valid until", "file"))
    return EXIT_OK


def cmd_trust(args: argparse.Namespace) -> int:
    from softplc.security.certificates import describe_file

    pki = _pki(args)
    try:
        path = pki.trust(args.certificate)
    except (ValueError, OSError) as error:
        print(f"softplc: opcua trust: {error}", file=sys.stderr)
        return EXIT_FAILURE
    info = describe_file(path)
    print(f"trusted: {info.subject if info else path.name} (SHA-256 {info.fingerprint if info else '?'}) → {path}")
    return EXIT_OK


def cmd_untrust(args: argparse.Namespace) -> int:
    pki = _pki(args)
    try:
        path = pki.untrust(args.fingerprint)
    except (ValueError, OSError) as error:
        print(f"softplc: opcua untrust: {error}", file=sys.stderr)
        return EXIT_FAILURE
    print(f"no longer trusted (moved to {path})")
    return EXIT_OK


# -- users ----------------------------------------------------------------------------------


def cmd_users_add(args: argparse.Namespace) -> int:
    from softplc.core.roles import Role
    from softplc.security.certificates import der_bytes, fingerprint, load_certificate_file

    store = _store(args)
    certificate = None
    password = None
    if args.certificate:
        candidate = Path(args.certificate)
        try:
            certificate = fingerprint(der_bytes(load_certificate_file(candidate))) if candidate.is_file() else args.certificate
        except ValueError as error:
            print(f"softplc: users add: {error}", file=sys.stderr)
            return EXIT_FAILURE
    else:
        password = _read_password(args)
        if password is None:
            return EXIT_FAILURE
    try:
        existed = args.name in store
        entry = store.add(args.name, Role(args.role), password=password, certificate=certificate)
    except ValueError as error:
        print(f"softplc: users add: {error}", file=sys.stderr)
        return EXIT_FAILURE
    how = "certificate" if entry.certificate else "password"
    print(f"{'updated' if existed else 'added'} user '{entry.name}' ({entry.role.value}, {how}) in {store.path}")
    return EXIT_OK


def _read_password(args: argparse.Namespace) -> str | None:
    from softplc.security.users import MIN_PASSWORD_LENGTH

    if args.password_stdin:
        password = sys.stdin.readline().rstrip("\r\n")
    elif not sys.stdin.isatty():
        print("softplc: users add: no terminal to ask for the password; use --password-stdin", file=sys.stderr)
        return None
    else:
        password = getpass.getpass(f"password for {args.name}: ")
        if getpass.getpass("again: ") != password:
            print("softplc: users add: the passwords differ", file=sys.stderr)
            return None
    if len(password) < MIN_PASSWORD_LENGTH:
        print(f"softplc: users add: the password must have at least {MIN_PASSWORD_LENGTH} characters", file=sys.stderr)
        return None
    return password


def cmd_users_list(args: argparse.Namespace) -> int:
    from softplc.util.console import print_table

    store = _store(args)
    entries = store.entries()
    print(f"users file: {store.path} ({plural(len(entries), 'user')})")
    if entries:
        rows = [[e.name, e.role.value, "certificate " + e.certificate[:16] if e.certificate else "password"] for e in entries]
        print_table(rows, ("name", "role", "login"))
    return EXIT_OK


def cmd_users_remove(args: argparse.Namespace) -> int:
    store = _store(args)
    try:
        store.remove(args.name)
    except KeyError:
        print(f"softplc: users remove: no user '{args.name}' in {store.path}", file=sys.stderr)
        return EXIT_FAILURE
    print(f"removed user '{args.name}' from {store.path}")
    return EXIT_OK

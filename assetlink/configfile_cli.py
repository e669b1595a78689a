"""`aerobase asset decrypt FILE [--password-file F]`: print a decrypted asset config file."""

from __future__ import annotations

import argparse
import getpass
import os
import stat
import sys
from collections.abc import Sequence
from pathlib import Path

from assetlink.configfile import ConfigFileError, decrypt_config

PASSWORD_ENV = "AEROBASE_ASSET_PASSWORD"


class PasswordSourceError(Exception):
    """The password could not be obtained; the message is one line."""


def read_password(password_file: str | None, *, prompt: bool = True) -> str:
    """The password: from a 0600 file, else AEROBASE_ASSET_PASSWORD, else a prompt."""
    if password_file:
        path = Path(password_file)
        try:
            mode = path.stat().st_mode
        except OSError as err:
            raise PasswordSourceError(f"cannot read password file {path}: {err.strerror}") from err
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            raise PasswordSourceError(
                f"password file {path} is readable by others (mode {stat.S_IMODE(mode):04o}); "
                "run: chmod 600 " + str(path)
            )
        return path.read_text(encoding="utf-8").rstrip("\r\n")
    if os.environ.get(PASSWORD_ENV):
        return os.environ[PASSWORD_ENV]
    if prompt and sys.stdin.isatty():
        return getpass.getpass("Asset configuration password: ")
    raise PasswordSourceError(f"no password: give --password-file or set {PASSWORD_ENV}")


def load_config(path: str | os.PathLike[str], password_file: str | None = None):  # type: ignore[no-untyped-def]
    """Read and decrypt a config file, taking the password from the usual sources."""
    password = read_password(password_file)
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise ConfigFileError(f"cannot read {path}: {err.strerror}") from err
    return decrypt_config(data, password)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `aerobase asset ...`."""
    parser = argparse.ArgumentParser(prog="aerobase asset")
    sub = parser.add_subparsers(dest="command", required=True)
    dec = sub.add_parser(
        "decrypt", help="print the decrypted content of an asset configuration file"
    )
    dec.add_argument("file")
    dec.add_argument("--password-file", help="file holding the password (mode 0600)")
    args = parser.parse_args(argv)
    try:
        cfg = load_config(args.file, args.password_file)
    except (ConfigFileError, PasswordSourceError) as err:
        print(f"aerobase asset decrypt: {err}", file=sys.stderr)
        return 1
    print(cfg.to_json())
    return 0

"""The asset configuration file reader bounds scrypt's cost before deriving (issue 14, item 9)."""

from __future__ import annotations

import time

import pytest

from assetlink.configfile import (
    _HEADER,
    KDF_LIMITS,
    MAGIC,
    VERSION,
    AssetConfig,
    BadFormat,
    KdfTooCostly,
    decrypt_config,
    encrypt_config,
)

CFG = AssetConfig("http://127.0.0.1:8000", "id", "uav-1", "uav", "s" * 43, "2026-11-24T00:00:00Z")


def _crafted(log_n: int, r: int, p: int) -> bytes:
    """A file whose header asks for these scrypt parameters (its ciphertext is junk)."""
    return _HEADER.pack(MAGIC, VERSION, log_n, r, p, b"\0" * 16, b"\0" * 12) + b"\0" * 64


@pytest.mark.parametrize(
    ("log_n", "r", "p"),
    [(22, 32, 16), (21, 8, 1), (20, 16, 1), (18, 8, 16), (20, 8, 2), (9, 8, 1), (15, 0, 1)],
)
def test_a_crafted_header_cannot_make_the_reader_derive_an_expensive_key(log_n, r, p):
    """Before: log_n 22, r 32, p 16 passed the check and scrypt asked for 16 GiB."""
    started = time.monotonic()
    with pytest.raises(KdfTooCostly) as err:
        decrypt_config(_crafted(log_n, r, p), "any-password")
    assert time.monotonic() - started < 0.5  # refused before deriving anything
    assert f"log2(N)={log_n}, r={r}, p={p}" in str(err.value)
    assert isinstance(err.value, BadFormat)  # the daemons already report BadFormat as one line


def test_the_bounds_admit_every_file_the_server_writes():
    """Server settings: log_n 10..20 (AEROBASE_CONFIG_SCRYPT_LOG_N), r 8, p 1."""
    for log_n in range(10, 21):
        KDF_LIMITS.check(log_n, 8, 1)
    data = encrypt_config(CFG, "right-password-1", log_n=10)
    assert decrypt_config(data, "right-password-1") == CFG


def test_the_writer_refuses_parameters_the_reader_would_refuse():
    """No file is ever written that the daemons cannot open."""
    with pytest.raises(ValueError, match="log2"):
        encrypt_config(CFG, "right-password-1", log_n=21)

"""The encrypted asset configuration file: written by the server, read by both daemons.

Format, version 1 (all integers unsigned, big-endian):

    offset  size  field
    0       4     magic b"ABCF"
    4       1     format version (1)
    5       1     scrypt log2(N)
    6       1     scrypt r
    7       1     scrypt p
    8       16    salt
    24      12    AES-GCM nonce
    36      ...   AES-128-GCM ciphertext of the UTF-8 JSON body, followed by the 16-byte tag

The 36-byte header is the GCM associated data, so a changed header fails authentication.
Key = scrypt(password, salt, N=2**log_n, r, p, length 16). The JSON body holds
`server_url`, `asset_id`, `name`, `kind`, `secret` and `issued_at`.

The header is read before the password is checked, so its key-derivation parameters are bounded
(KDF_LIMITS) before deriving: scrypt needs 128·r·N bytes and N·r·p block mixes, and a crafted file
asking for log_n 22, r 32, p 16 would take 16 GiB. The bounds admit everything the server writes
(log_n 10..20, r 8, p 1: at most 1 GiB) and nothing costlier.
"""

from __future__ import annotations

import json
import os
import struct
from dataclasses import asdict, dataclass

from cryptography.exceptions import InvalidTag
from cryptography.hazmat.primitives.ciphers.aead import AESGCM
from cryptography.hazmat.primitives.kdf.scrypt import Scrypt

MAGIC = b"ABCF"
VERSION = 1
_HEADER = struct.Struct(">4sBBBB16s12s")
HEADER_SIZE = _HEADER.size  # 36
TAG_SIZE = 16


class ConfigFileError(Exception):
    """The file cannot be read; the message is one line fit for a user."""


class WrongPassword(ConfigFileError):
    """Authentication failed: the password is wrong or the file was altered."""


class BadFormat(ConfigFileError):
    """Not an Aerobase asset file, a version we do not know, or a truncated file."""


class KdfTooCostly(BadFormat):
    """The file asks for key-derivation parameters beyond what any file of ours uses."""


@dataclass(frozen=True)
class KdfLimits:
    """The scrypt parameters a file may ask for."""

    min_log_n: int = 10
    max_log_n: int = 20
    max_r: int = 16
    max_p: int = 4
    max_memory_bytes: int = 1 << 30  # 128·r·N
    max_work: int = (1 << 20) * 8  # N·r·p, what the server's costliest setting needs

    def check(self, log_n: int, r: int, p: int) -> None:
        """Raise KdfTooCostly unless (log_n, r, p) is within the limits."""
        memory = 128 * r * (1 << log_n)
        work = (1 << log_n) * r * p
        if (
            self.min_log_n <= log_n <= self.max_log_n
            and 1 <= r <= self.max_r
            and 1 <= p <= self.max_p
            and memory <= self.max_memory_bytes
            and work <= self.max_work
        ):
            return
        raise KdfTooCostly(
            f"the asset configuration file asks for scrypt log2(N)={log_n}, r={r}, p={p} "
            f"({memory / (1 << 20):.0f} MiB of memory, {work} block mixes); this reader accepts "
            f"log2(N) {self.min_log_n}..{self.max_log_n}, r <= {self.max_r}, p <= {self.max_p}, "
            f"at most {self.max_memory_bytes >> 20} MiB and {self.max_work} block mixes"
        )


KDF_LIMITS = KdfLimits()


@dataclass(frozen=True)
class AssetConfig:
    """What an asset daemon needs to reach its server and prove who it is."""

    server_url: str
    asset_id: str
    name: str
    kind: str
    secret: str
    issued_at: str

    def to_json(self) -> str:
        """The body as pretty JSON."""
        return json.dumps(asdict(self), indent=2)


def _key(password: str, salt: bytes, log_n: int, r: int, p: int) -> bytes:
    return Scrypt(salt=salt, length=16, n=2**log_n, r=r, p=p).derive(password.encode("utf-8"))


def encrypt_config(
    cfg: AssetConfig, password: str, log_n: int = 15, r: int = 8, p: int = 1
) -> bytes:
    """Encrypt `cfg` with a key derived from `password`; returns the file's bytes."""
    try:
        KDF_LIMITS.check(log_n, r, p)  # never write a file the daemons refuse to read
    except KdfTooCostly as err:
        raise ValueError(str(err)) from err
    salt, nonce = os.urandom(16), os.urandom(12)
    header = _HEADER.pack(MAGIC, VERSION, log_n, r, p, salt, nonce)
    body = json.dumps(asdict(cfg), separators=(",", ":")).encode()
    return header + AESGCM(_key(password, salt, log_n, r, p)).encrypt(nonce, body, header)


def decrypt_config(data: bytes, password: str) -> AssetConfig:
    """Decrypt a configuration file; raises a ConfigFileError with a one-line reason."""
    if len(data) < HEADER_SIZE or data[:4] != MAGIC:
        raise BadFormat("not an Aerobase asset configuration file")
    _magic, version, log_n, r, p, salt, nonce = _HEADER.unpack(data[:HEADER_SIZE])
    if version != VERSION:
        raise BadFormat(
            f"unsupported asset configuration file version {version} (this build reads {VERSION})"
        )
    if len(data) < HEADER_SIZE + TAG_SIZE:
        raise BadFormat("the asset configuration file is truncated")
    KDF_LIMITS.check(log_n, r, p)
    try:
        body = AESGCM(_key(password, salt, log_n, r, p)).decrypt(
            nonce, data[HEADER_SIZE:], data[:HEADER_SIZE]
        )
    except InvalidTag as err:
        raise WrongPassword(
            "wrong password, or the file was altered (AES-GCM cannot tell the two apart)"
        ) from err
    try:
        fields = json.loads(body)
        return AssetConfig(**{k: str(fields[k]) for k in AssetConfig.__dataclass_fields__})
    except (ValueError, KeyError, TypeError) as err:
        raise BadFormat(
            "the asset configuration file decrypted but its content is not valid"
        ) from err

"""Wrong passwords already checked, so that the same one again is answered without a count.

A client that retries stale credentials (a rover whose password was changed, a script with an
old secret) sends the same wrong password over and over. Checked again, each try would cost a
password hash and a place under the failed-login limits, and soon shut out every client at that
address and account, the ones holding the right password included. Yet a repeat tells its sender
nothing new: a password that did not match a stored hash still does not match it. So a failure is
remembered, keyed by an HMAC of (account, address, password) under a key that lives only in this
process, with the hash it failed against; the same password from the same address is answered
wrong at once while the account's hash is unchanged. The address is part of the key, so a guesser
cannot learn from the speed of an answer which passwords someone else has tried (a user's typos
lie near the right password). Bounded: the oldest entries go first, and each lasts one window.

The same memory, of passwords that matched, lets a long-lived NTRIP stream be checked again
against its account's current hash without a password hash each time: a password that matched
hash H still matches H; only when the hash has changed (the password changed or was reset) is
the password verified again (server/stations/service.py).
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import time
from collections import OrderedDict

_ABSENT = "-"  # the hash of an account that does not exist


class CheckedPasswords:
    """Passwords checked against a hash in the last `ttl_s` seconds, with the hash they were
    checked against; at most `size` of them. One instance holds one outcome: `guesses` the
    wrong ones, `verified` the right ones (server/auth/limiter.py)."""

    def __init__(self, ttl_s: float, size: int = 10_000) -> None:
        self.ttl_s, self.size = ttl_s, size
        self._key = secrets.token_bytes(32)
        self._seen: OrderedDict[bytes, tuple[str, float]] = OrderedDict()

    def _digest(self, account: str, addr: str | None, password: str) -> bytes:
        data = "\0".join((account.lower(), addr or "", password)).encode("utf-8", "surrogatepass")
        return hmac.digest(self._key, data, hashlib.sha256)

    def known(
        self, account: str, addr: str | None, password: str, password_hash: str | None
    ) -> bool:
        """Whether this password was checked against this very hash, from this address, lately."""
        digest = self._digest(account, addr, password)
        seen = self._seen.get(digest)
        if seen is None:
            return False
        checked_against, until = seen
        if time.monotonic() >= until:
            del self._seen[digest]
            return False
        return hmac.compare_digest(checked_against, password_hash or _ABSENT)

    def remember(
        self, account: str, addr: str | None, password: str, password_hash: str | None
    ) -> None:
        """Note a password checked against `password_hash` (None: no such account)."""
        digest = self._digest(account, addr, password)
        self._seen.pop(digest, None)
        self._seen[digest] = (password_hash or _ABSENT, time.monotonic() + self.ttl_s)
        while len(self._seen) > self.size:
            self._seen.popitem(last=False)

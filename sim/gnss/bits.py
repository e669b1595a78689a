"""A big-endian bit writer for RTCM3 payloads (fields of any width, MSB first)."""

from __future__ import annotations


class BitWriter:
    """Appends unsigned and two's-complement fields MSB first; pads to whole bytes on output."""

    def __init__(self) -> None:
        self._value = 0
        self._nbits = 0

    @property
    def nbits(self) -> int:
        """Number of bits written so far."""
        return self._nbits

    def uint(self, value: int, bits: int) -> BitWriter:
        """Append `value` as an unsigned field of `bits` bits."""
        if bits <= 0:
            raise ValueError("field width must be positive")
        if not 0 <= value < (1 << bits):
            raise ValueError(f"{value} does not fit in an unsigned {bits}-bit field")
        self._value = (self._value << bits) | value
        self._nbits += bits
        return self

    def sint(self, value: int, bits: int) -> BitWriter:
        """Append `value` as a two's-complement signed field of `bits` bits."""
        if bits <= 1:
            raise ValueError("signed field width must be at least 2")
        limit = 1 << (bits - 1)
        if not -limit <= value < limit:
            raise ValueError(f"{value} does not fit in a signed {bits}-bit field")
        return self.uint(value & ((1 << bits) - 1), bits)

    def flag(self, value: bool) -> BitWriter:
        """Append one bit."""
        return self.uint(1 if value else 0, 1)

    def to_bytes(self) -> bytes:
        """The bits written, zero-padded at the end to a whole number of bytes."""
        pad = (-self._nbits) % 8
        nbytes = (self._nbits + pad) // 8
        return (self._value << pad).to_bytes(nbytes, "big")

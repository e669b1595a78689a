"""The Content-Disposition header of a download whose file name comes from user data (RFC 6266)."""

from __future__ import annotations

import re
import unicodedata
from urllib.parse import quote

# categories never wanted in a file name: controls, format characters (bidi overrides,
# zero-width), line and paragraph separators (U+2028, U+2029), unassigned and surrogates
_UNSAFE_CATEGORIES = {"Cc", "Cf", "Zl", "Zp", "Cn", "Cs", "Co"}


def _clean(name: str) -> str:
    """`name` as one file name: no folders, no unsafe characters, no leading dots or "_"."""
    kept = "".join(
        "_" if c in '/\\"' or unicodedata.category(c) in _UNSAFE_CATEGORIES else c
        for c in unicodedata.normalize("NFC", name)
    )
    return kept.strip().lstrip("._ ").strip()


def _ascii_fallback(name: str) -> str:
    """The name in printable ASCII for clients that ignore `filename*`; others become "_"."""
    folded = unicodedata.normalize("NFKD", name).encode("ascii", "ignore").decode("ascii")
    return re.sub(r"[^A-Za-z0-9 ._()+-]+", "_", folded if folded.strip() else name).strip()


def attachment(name: str, suffix: str = "", default: str = "download") -> str:
    """`attachment; filename="<ASCII>"; filename*=UTF-8''<percent-encoded>` for `name + suffix`.

    The name can be anything a user typed (`../../etc/passwd`, `"; filename=evil.sh`, Cyrillic,
    U+2028): path separators, quotes and invisible characters are replaced, the UTF-8 form goes in
    `filename*` (RFC 5987 percent-encoding, which browsers prefer) and a safe ASCII form in
    `filename`, so the header is always valid Latin-1 and one parameter of each kind.
    """
    stem = _clean(name)[:120] or default
    ascii_stem = _ascii_fallback(stem).strip("._ ") or default
    fallback = f"{ascii_stem}{suffix}"
    full = f"{stem}{suffix}"
    if full == fallback:
        return f'attachment; filename="{fallback}"'
    return f"attachment; filename=\"{fallback}\"; filename*=UTF-8''{quote(full, safe='')}"

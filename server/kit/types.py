"""Request field types that every schema shares: bounded text without NUL bytes."""

from __future__ import annotations

import re
from typing import Annotated

from pydantic import AfterValidator, StringConstraints


def _no_control(value: str) -> str:
    if "\x00" in value:
        raise ValueError("must not contain NUL characters")
    return value


def _email(value: str) -> str:
    value = value.strip().lower()
    if not re.fullmatch(r"[^@\s]{1,64}@[^@\s]{1,255}", value):
        raise ValueError("not an e-mail address")
    return value


def _name(value: str) -> str:
    if any(ord(c) < 32 for c in value):
        raise ValueError("must not contain control characters")
    return value


Text = Annotated[str, StringConstraints(max_length=2000), AfterValidator(_no_control)]
Name = Annotated[
    str,
    StringConstraints(min_length=1, max_length=100, strip_whitespace=True),
    AfterValidator(_name),
]
Email = Annotated[str, StringConstraints(min_length=3, max_length=320), AfterValidator(_email)]
Password = Annotated[
    str, StringConstraints(min_length=12, max_length=1024), AfterValidator(_no_control)
]
LoginPassword = Annotated[
    str, StringConstraints(min_length=1, max_length=1024), AfterValidator(_no_control)
]

"""A property test of the outbox against a model server: cuts, lost acks, restarts, overflow.

Whatever happens, the server sees contiguous seqs, stores every message at most once and
in order, and every message it never got was counted as dropped at the bound.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule

from assetlink.outbox import Outbox
from protocol import messages as m
from protocol.codec import decode

MAX_ENTRIES = 8


class OutboxAgainstServer(RuleBasedStateMachine):
    """The link's outbox on one side, a server storing the highest contiguous seq on the other."""

    def __init__(self) -> None:
        super().__init__()
        self.dir = Path(tempfile.mkdtemp())
        self.box = Outbox(self.dir / "link.sqlite", max_entries=MAX_ENTRIES)
        self.appended = 0
        self.wire: list[tuple[int, int]] = []  # (seq, i) sent, not yet received
        self.server_last = 0
        self.stored: list[int] = []

    @rule(n=st.integers(1, 6))
    def append(self, n: int) -> None:
        for _ in range(n):
            payload = m.EventPayload(name="tick", data={"i": self.appended})
            self.box.append("event", payload.model_dump_json())
            self.appended += 1

    @rule(k=st.integers(1, 6))
    def send(self, k: int) -> None:
        for entry in self.box.take(k):
            msg = decode(entry.text, "asset_to_server")
            assert isinstance(msg, m.Event) and msg.seq == entry.seq
            self.wire.append((msg.seq, msg.payload.data["i"]))

    @rule(k=st.integers(1, 6))
    def server_receives(self, k: int) -> None:
        for seq, i in self.wire[:k]:
            assert seq == self.server_last + 1, "the server must never see a gap"
            self.server_last = seq
            self.stored.append(i)
        del self.wire[:k]

    @rule()
    def ack_arrives(self) -> None:
        self.box.ack(self.server_last)

    @rule()
    def link_cut(self) -> None:
        self.wire.clear()
        self.box.resume(self.server_last)

    @rule()
    def daemon_restarts(self) -> None:
        self.wire.clear()
        self.box.close()
        self.box = Outbox(self.dir / "link.sqlite", max_entries=MAX_ENTRIES)
        self.box.resume(self.server_last)

    @invariant()
    def bounded_ordered_unique(self) -> None:
        assert len(self.box) <= MAX_ENTRIES
        assert self.stored == sorted(set(self.stored))

    def teardown(self) -> None:
        try:
            self.link_cut()
            for _ in range(MAX_ENTRIES):
                self.send(MAX_ENTRIES)
                self.server_receives(MAX_ENTRIES)
                self.ack_arrives()
            assert len(self.box) == 0, "a reconnected outbox drains completely"
            assert self.stored == sorted(set(self.stored))
            assert self.appended - len(self.stored) <= self.box.dropped_total()
        finally:
            self.box.close()
            shutil.rmtree(self.dir, ignore_errors=True)


OutboxAgainstServer.TestCase.settings = settings(
    max_examples=60, stateful_step_count=40, deadline=None
)
test_outbox_against_server = pytest.mark.slow(OutboxAgainstServer.TestCase)

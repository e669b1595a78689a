"""The link's SQLite outbox: bounds, persistence, acks, seq numbering, token, ledger."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest

from assetlink.outbox import AsyncOutbox, Outbox, Token
from assetlink.statefile import StateFileError
from protocol import messages as m
from protocol import telemetry_payloads as t
from protocol.codec import decode


def event(i: int) -> str:
    return m.EventPayload(name="tick", data={"i": i}).model_dump_json()


def numbers(entries) -> list[int]:
    out = []
    for entry in entries:
        msg = decode(entry.text, "asset_to_server")
        assert isinstance(msg, m.Event), msg
        assert msg.seq == entry.seq
        out.append(msg.payload.data["i"])
    return out


@pytest.fixture
def path(tmp_path: Path) -> Path:
    return tmp_path / "link.sqlite"


def test_take_numbers_in_queue_order_and_texts_decode(path: Path) -> None:
    box = Outbox(path)
    for i in range(5):
        box.append("event", event(i))
    box.append("telemetry", t.UavTelemetry(armed=True).model_dump_json())
    taken = box.take(4) + box.take(10)
    assert [e.seq for e in taken] == [1, 2, 3, 4, 5, 6]
    assert numbers(taken[:5]) == [0, 1, 2, 3, 4]
    tele = decode(taken[5].text, "asset_to_server")
    assert isinstance(tele, m.Telemetry) and tele.payload.armed
    assert box.take(10) == []
    assert len(box) == 6 and box.in_flight() == 6


def test_result_entries_carry_re(path: Path) -> None:
    box = Outbox(path)
    cid = "9d3e1a42-7c55-4b8e-8f10-2a6b4c8d0e13"
    box.append(
        "command_result", m.CommandResultPayload(status="succeeded").model_dump_json(), re=cid
    )
    msg = decode(box.take(1)[0].text, "asset_to_server")
    assert isinstance(msg, m.CommandResult) and str(msg.re) == cid


def test_bound_drops_oldest_and_counts(path: Path) -> None:
    box = Outbox(path, max_entries=5)
    drops = [box.append("event", event(i)) for i in range(8)]
    assert drops == [0, 0, 0, 0, 0, 1, 1, 1]
    assert len(box) == 5
    assert box.dropped_total() == 3 and box.dropped_unreported() == 3
    assert numbers(box.take(10)) == [3, 4, 5, 6, 7]


def test_drop_report_is_one_event_and_resets(path: Path) -> None:
    box = Outbox(path, max_entries=4)
    for i in range(6):
        box.append("event", event(i))
    assert box.report_drops() == 3  # two at the bound, one to make room for the report
    assert box.report_drops() == 0
    assert box.dropped_total() == 3 and box.dropped_unreported() == 0
    queued = box.take(10)
    assert len(queued) == 4
    last = decode(queued[-1].text, "asset_to_server")
    assert isinstance(last, m.Event)
    assert last.payload.name == "outbox_overflow" and last.payload.severity == "warning"
    assert last.payload.data["dropped"] == 3


def test_ack_deletes_up_to_seq(path: Path) -> None:
    box = Outbox(path)
    for i in range(5):
        box.append("event", event(i))
    box.take(5)
    assert box.ack(3) == 3
    assert box.ack(3) == 0
    assert len(box) == 2 and box.in_flight() == 2


def test_everything_persists_across_reopen(path: Path) -> None:
    box = Outbox(path, max_entries=3)
    stream = box.stream_id
    for i in range(5):
        box.append("event", event(i))
    box.take(2)
    box.ack(1)
    box.close()
    again = Outbox(path, max_entries=3)
    assert again.stream_id == stream
    assert len(again) == 2 and again.dropped_total() == 2
    assert again.next_seq == 3
    assert again.resume(1) == (0, 2)
    assert [e.seq for e in again.take(10)] == [2, 3]
    assert numbers(again.take(10)) == []


def test_seq_continues_across_restart(path: Path) -> None:
    box = Outbox(path)
    for i in range(3):
        box.append("event", event(i))
    box.take(3)
    box.ack(3)
    box.close()
    again = Outbox(path)
    again.append("event", event(3))
    assert [e.seq for e in again.take(1)] == [4]


def test_resume_deletes_what_the_server_has_and_renumbers_the_rest(path: Path) -> None:
    box = Outbox(path)
    for i in range(6):
        box.append("event", event(i))
    box.take(6)  # sent 1..6, no ack received before the cut
    assert box.resume(4) == (4, 2)  # the server stored 1..4
    replay = box.take(10)
    assert [e.seq for e in replay] == [5, 6]
    assert numbers(replay) == [4, 5]


def test_resume_after_drops_leaves_no_gap(path: Path) -> None:
    box = Outbox(path, max_entries=4)
    for i in range(4):
        box.append("event", event(i))
    box.take(2)  # 1, 2 in flight; the link dies
    for i in range(4, 9):
        box.append("event", event(i))  # the cut: 0..4 dropped at the bound
    assert box.resume(0) == (0, 4)
    replay = box.take(10)
    assert [e.seq for e in replay] == [1, 2, 3, 4]  # contiguous for the server's ack
    assert numbers(replay) == [5, 6, 7, 8]


def test_resume_follows_a_server_ahead_of_us(path: Path) -> None:
    box = Outbox(path)
    box.append("event", event(0))
    box.resume(41)
    assert [e.seq for e in box.take(1)] == [42]


def test_token_persists_and_clears(path: Path) -> None:
    box = Outbox(path)
    assert path.stat().st_mode & 0o077 == 0  # the token is for the owner's eyes only
    assert box.load_token() is None
    box.save_token(Token("abc", 1_900_000_000.5))
    box.close()
    again = Outbox(path)
    assert again.load_token() == Token("abc", 1_900_000_000.5)
    again.save_token(None)
    assert again.load_token() is None


def test_command_ledger_records_first_result_once(path: Path) -> None:
    box = Outbox(path)
    cid = "5b1e8c44-0f0e-4a5e-9d7a-1f4c3b2a6e90"
    assert box.begin_command(cid, "open_base") is None
    again = box.begin_command(cid, "open_base")
    assert again is not None and again.state == "running"
    progress = m.CommandResultPayload(status="in_progress").model_dump_json()
    box.progress_command(cid, progress)
    first = m.CommandResultPayload(status="succeeded", reason="first").model_dump_json()
    second = m.CommandResultPayload(status="failed", reason="second").model_dump_json()
    assert box.finish_command(cid, first)
    assert not box.finish_command(cid, second)
    queued = [decode(e.text, "asset_to_server") for e in box.take(10)]
    assert [q.payload.status for q in queued] == ["in_progress", "succeeded"]
    box.close()
    record = Outbox(path).command(cid)
    assert record is not None and record.state == "done"
    assert json.loads(record.result)["reason"] == "first"


def test_prune_forgets_only_old_finished_commands(path: Path) -> None:
    box = Outbox(path)
    box.begin_command("a", "x")
    box.finish_command("a", m.CommandResultPayload(status="succeeded").model_dump_json())
    box.begin_command("b", "x")
    assert box.prune_commands(older_than_ms=m.now_ms() + 1000) == 1
    assert box.command("a") is None and box.command("b") is not None


def test_bad_arguments_are_refused(path: Path) -> None:
    with pytest.raises(ValueError):
        Outbox(path, max_entries=0)
    with pytest.raises(ValueError):
        Outbox(path, synchronous="sometimes")


async def test_async_outbox_runs_on_its_own_thread(path: Path) -> None:
    box = await AsyncOutbox.open(path, max_entries=10)
    try:
        worker = await box.call(threading.get_ident)
        assert worker != threading.get_ident()
        await box.append("event", event(1))
        taken = await box.take(5)
        assert [e.seq for e in taken] == [1]
        assert await box.ack(1) == 1
        assert len(box.sync) == 0
    finally:
        await box.close()


def test_a_state_file_that_cannot_be_created_is_one_clear_error_naming_it(tmp_path: Path):
    """A deployment whose state folder is missing (or not the daemon user's) gets one line that
    names the file and what it needs, which the daemons print before exiting 1."""
    path = tmp_path / "no-such-folder" / "agent-link.db"
    with pytest.raises(StateFileError) as err:
        Outbox(path, 10)
    assert str(path) in str(err.value) and "writable" in str(err.value)
    assert isinstance(err.value, OSError)

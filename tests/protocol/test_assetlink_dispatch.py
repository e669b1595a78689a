"""Inbound commands: each id runs once, redeliveries (even after a restart) get the first result."""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from assetlink.dispatch import CommandDispatcher, CommandRequest, result
from assetlink.outbox import AsyncOutbox
from protocol import messages as m
from protocol.codec import decode
from protocol.vocabulary import StartCharging, UploadMission
from tests.polling import eventually


def command(
    name: str, cid: uuid.UUID | None = None, deadline_in_s: float = 60, **params
) -> m.Command:
    payload = m.CommandPayload(
        name=name, params=params, deadline=m.now_ms() + int(deadline_in_s * 1000)
    )
    return m.envelope(payload, id=cid or uuid.uuid4())  # type: ignore[return-value]


async def results(box: AsyncOutbox) -> list[m.CommandResult]:
    """Every command_result queued so far, in order (taken for sending)."""
    out = []
    for entry in await box.take(1000):
        msg = decode(entry.text, "asset_to_server")
        assert isinstance(msg, m.CommandResult), msg
        out.append(msg)
    return out


@pytest.fixture
async def box(tmp_path: Path):
    outbox = await AsyncOutbox.open(tmp_path / "link.sqlite")
    yield outbox
    await outbox.close()


class Counter:
    def __init__(self) -> None:
        self.calls: list[CommandRequest] = []
        self.release = asyncio.Event()

    async def plain(self, request: CommandRequest) -> m.CommandResultPayload:
        self.calls.append(request)
        return result("succeeded", "done", {"n": len(self.calls)})

    async def steps(self, request: CommandRequest) -> AsyncIterator[object]:
        self.calls.append(request)
        yield m.CommandProgress(step="panels", index=1, total=2, message="opening panels")
        await self.release.wait()
        yield m.CommandProgress(step="lift", index=2, total=2, message="raising lift")
        yield result("succeeded", "open")


async def test_plain_handler_runs_once_and_redelivery_gets_the_first_result(box) -> None:
    counter = Counter()
    queued = []
    dispatcher = CommandDispatcher(box, lambda: queued.append(1))
    dispatcher.register(StartCharging, counter.plain)
    cmd = command("start_charging", current_limit_ma=1500)
    await dispatcher.handle(cmd)
    await eventually(lambda: not dispatcher.running)
    await dispatcher.handle(cmd)
    assert len(counter.calls) == 1
    assert counter.calls[0].command == StartCharging(current_limit_ma=1500)
    assert counter.calls[0].id == cmd.id
    first, again = await results(box)
    assert first.re == again.re == cmd.id
    assert first.payload == again.payload
    assert first.payload.status == "succeeded" and first.payload.data == {"n": 1}
    assert first.id != again.id
    assert dispatcher.stats.executed == 1 and dispatcher.stats.redelivered == 1
    assert queued


async def test_progress_then_exactly_one_final_result(box) -> None:
    counter = Counter()
    dispatcher = CommandDispatcher(box)
    dispatcher.register("open", counter.steps)
    cmd = command("open")
    await dispatcher.handle(cmd)
    await eventually(lambda: len(counter.calls) == 1 and len(box.sync) == 1)
    await dispatcher.handle(cmd)  # redelivered while running: answered, not run again
    counter.release.set()
    await eventually(lambda: not dispatcher.running)
    got = await results(box)
    assert [r.payload.status for r in got] == [
        "in_progress",
        "in_progress",
        "in_progress",
        "succeeded",
    ]
    assert got[1].payload.progress == got[0].payload.progress  # the current progress, re-sent
    assert got[2].payload.progress is not None and got[2].payload.progress.step == "lift"
    assert got[3].payload.reason == "open"
    assert len(counter.calls) == 1


async def test_redelivery_after_restart_is_not_executed(tmp_path: Path) -> None:
    path = tmp_path / "link.sqlite"
    counter = Counter()
    cmd = command("open")
    box = await AsyncOutbox.open(path)
    dispatcher = CommandDispatcher(box)
    dispatcher.register("open", counter.plain)
    await dispatcher.handle(cmd)
    await eventually(lambda: not dispatcher.running)
    first = (await results(box))[0]
    await box.close()

    box = await AsyncOutbox.open(path)
    try:
        dispatcher = CommandDispatcher(box)
        dispatcher.register("open", counter.plain)
        assert await dispatcher.recover() == 0
        await dispatcher.handle(cmd)
        (again,) = await results(box)
        assert again.payload == first.payload
        assert len(counter.calls) == 1
    finally:
        await box.close()


async def test_command_interrupted_by_a_restart_fails_and_never_reruns(tmp_path: Path) -> None:
    path = tmp_path / "link.sqlite"
    counter = Counter()
    cmd = command("open")
    box = await AsyncOutbox.open(path)
    dispatcher = CommandDispatcher(box)
    dispatcher.register("open", counter.steps)
    await dispatcher.handle(cmd)
    await eventually(lambda: len(box.sync) == 1)
    # The process dies: no cancellation runs, the ledger still says "running".
    await box.close()
    for task in asyncio.all_tasks():
        if task.get_name().startswith("command-open"):
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)

    box = await AsyncOutbox.open(path)
    try:
        dispatcher = CommandDispatcher(box)
        dispatcher.register("open", counter.steps)
        assert await dispatcher.recover() == 1
        await dispatcher.handle(cmd)
        statuses = [r.payload.status for r in await results(box)]
        assert statuses == ["in_progress", "failed", "failed"]
        assert len(counter.calls) == 1
    finally:
        await box.close()


async def test_unknown_command_is_rejected(box) -> None:
    dispatcher = CommandDispatcher(box)
    await dispatcher.handle(command("fly_to_the_moon"))
    (got,) = await results(box)
    assert got.payload.status == "rejected" and "fly_to_the_moon" in got.payload.reason


async def test_past_deadline_times_out_without_running(box) -> None:
    counter = Counter()
    dispatcher = CommandDispatcher(box)
    dispatcher.register("open", counter.plain)
    await dispatcher.handle(command("open", deadline_in_s=-1))
    (got,) = await results(box)
    assert got.payload.status == "timed_out" and not counter.calls


async def test_exceptions_and_bad_outputs_become_failed(box) -> None:
    async def broken(request: CommandRequest) -> None:
        raise RuntimeError("lift jammed")

    async def wrong(request: CommandRequest) -> dict:
        return {"not": "a result"}

    async def not_final(request: CommandRequest):
        yield result("in_progress")
        yield 42

    dispatcher = CommandDispatcher(box)
    dispatcher.register("stop", broken)
    dispatcher.register("close", wrong)
    dispatcher.register("lift_up", not_final)
    for name in ("stop", "close", "lift_up"):
        await dispatcher.handle(command(name))
        await eventually(lambda: not dispatcher.running)
    got = [(r.payload.status, r.payload.reason) for r in await results(box)]
    assert got[0] == ("failed", "RuntimeError: lift jammed")
    assert got[1][0] == "failed" and "dict" in got[1][1]
    assert got[2][0] == "in_progress"
    assert got[3][0] == "failed" and "int" in got[3][1]


async def test_none_means_success_and_generator_without_final_succeeds(box) -> None:
    async def quiet(request: CommandRequest) -> None:
        return None

    async def only_progress(request: CommandRequest):
        yield m.CommandProgress(step="a", index=1, total=1)

    dispatcher = CommandDispatcher(box)
    dispatcher.register("pause", quiet)
    dispatcher.register("resume", only_progress)
    await dispatcher.handle(command("pause"))
    await dispatcher.handle(command("resume"))
    await eventually(lambda: not dispatcher.running)
    statuses = sorted(r.payload.status for r in await results(box))
    assert statuses == ["in_progress", "succeeded", "succeeded"]


async def test_stop_cancels_running_commands_with_a_result(box) -> None:
    counter = Counter()
    dispatcher = CommandDispatcher(box)
    dispatcher.register("open", counter.steps)
    cmd = command("open")
    await dispatcher.handle(cmd)
    await eventually(lambda: len(box.sync) == 1)
    await dispatcher.stop()
    got = await results(box)
    assert [r.payload.status for r in got] == ["in_progress", "canceled"]
    await dispatcher.handle(cmd)
    assert (await results(box))[0].payload.status == "canceled"


async def test_params_that_do_not_fit_are_rejected_naming_the_field(box) -> None:
    counter = Counter()
    dispatcher = CommandDispatcher(box)
    dispatcher.register(StartCharging, counter.plain)
    dispatcher.register(UploadMission, counter.plain)
    await dispatcher.handle(command("start_charging", current_limit_ma="lots"))
    await dispatcher.handle(
        command("upload_mission", items=[{"command": 16, "lat": 123.0, "lon": 0, "alt": 10}])
    )
    await dispatcher.handle(command("start_charging", current_limit_ma=500, voltage=12))
    got = [(r.payload.status, r.payload.reason) for r in await results(box)]
    assert [status for status, _ in got] == ["rejected"] * 3
    assert "current_limit_ma" in got[0][1]
    assert "items.0.lat" in got[1][1]
    assert "voltage" in got[2][1]
    assert not counter.calls and dispatcher.stats.rejected == 3


def test_only_commands_of_the_vocabulary_can_be_registered(box) -> None:
    dispatcher = CommandDispatcher(box)
    with pytest.raises(ValueError, match="teleport"):
        dispatcher.register("teleport", Counter().plain)

"""Stage shares of the server's hot path from a py-spy profile.

    py-spy record -p <server pid> -d 10 -r 200 --gil --threads -f raw -o server.raw
    python bench/profile_stages.py server.raw [seconds] [rate]

`--gil` keeps the samples of the thread holding the GIL (the aiosqlite and anyio threads' idle
waits do not count). Each sample goes to the stage of its innermost matching frame; work under an
asset session's periodic tasks (command sweep, heartbeat) is counted apart.
"""

from __future__ import annotations

import collections
import sys

STAGES = [
    ("decode + validate", ["protocol/codec.py", "pydantic/type_adapter", "msgspec", "fastpath"]),
    ("fan-out serialise", ["model_dump", "json/encoder", "json/__init__", "orjson"]),
    (
        "store (ORM/Core, flatten, aiosqlite/asyncpg)",
        ["server/telemetry/", "server/realtime/ingest.py", "sqlalchemy/", "aiosqlite/", "asyncpg/"],
    ),
    (
        "websocket frames and socket writes (native.py, rfc6455.py; before: uvicorn, starlette)",
        [
            "websockets/",
            "uvicorn/",
            "starlette/",
            "realtime/frames.py",
            "realtime/sender.py",
            "realtime/native.py",
            "realtime/rfc6455.py",
            "realtime/asgi_socket.py",
        ],
    ),
    ("ack", ["acker", "AckPayload"]),
    ("broker + operator forward", ["realtime/broker.py", "realtime/operator_session.py"]),
    ("session read loop", ["realtime/asset_session.py"]),
    ("event loop, tasks, futures", ["asyncio/", "uvloop", "Runner.run"]),
]
PERIODIC = ("deliver_commands", "AssetSession.heartbeat", "_keep_slot")


def classify(stack: str) -> str:
    """The stage of one sampled stack (`thread;frame;frame;...`)."""
    frames = stack.split(";")[1:]
    if any(k in f for f in frames for k in PERIODIC):
        return "per-socket periodic work (command sweep, heartbeat)"
    for frame in reversed(frames):
        for name, keys in STAGES:
            if any(k in frame for k in keys):
                return name
    return "other"


def main(argv: list[str]) -> int:
    """Print the shares as a Markdown table."""
    if not argv:
        print(__doc__)
        return 2
    seconds = float(argv[1]) if len(argv) > 1 else 10.0
    rate = float(argv[2]) if len(argv) > 2 else 200.0
    counts: collections.Counter[str] = collections.Counter()
    with open(argv[0]) as f:
        for line in f:
            stack, _, n = line.rstrip().rpartition(" ")
            counts[classify(stack)] += int(n)
    total = sum(counts.values()) or 1
    print(f"samples holding the GIL: {total} ({100 * total / (seconds * rate):.0f} % of one core)")
    print("| stage | share |\n|---|---|")
    for name, n in counts.most_common():
        print(f"| {name} | {100 * n / total:.0f} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

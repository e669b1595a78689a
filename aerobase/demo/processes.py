"""The demo's child processes (world, server, daemons), started and stopped together."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import httpx


def say(message: str) -> None:
    """One line of the demo's own output, timestamped."""
    print(f"[demo {datetime.now().strftime('%H:%M:%S')}] {message}", flush=True)


class Processes:
    """The child processes, stopped together (SIGINT, then SIGTERM, then SIGKILL)."""

    def __init__(self, folder: Path) -> None:
        """Children's logs go to `folder`/<name>.log."""
        self.folder = folder
        self.children: list[tuple[str, subprocess.Popen[bytes]]] = []

    def start(self, name: str, args: list[str], env: dict[str, str]) -> subprocess.Popen[bytes]:
        """Start `aerobase <args>` as a child called `name`, with `env` added to ours."""
        log = open(self.folder / f"{name}.log", "ab")  # a restart adds to the first log
        proc = subprocess.Popen(
            [sys.executable, "-m", "aerobase.cli", *args],
            env={**os.environ, **env},
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        self.children.append((name, proc))
        return proc

    def forget(self, name: str) -> None:
        """Stop watching the exited child `name` (before starting it again)."""
        self.children = [(n, p) for n, p in self.children if n != name or p.poll() is None]

    def check(self) -> None:
        """Raise RuntimeError if a child has exited."""
        for name, proc in self.children:
            if proc.poll() is not None:
                raise RuntimeError(
                    f"{name} exited with {proc.returncode}; see {self.folder / (name + '.log')}"
                )

    def stop(self) -> None:
        """Stop every child, more firmly each round."""
        for sig, wait in ((signal.SIGINT, 10), (signal.SIGTERM, 5), (signal.SIGKILL, 5)):
            alive = [(n, p) for n, p in self.children if p.poll() is None]
            for _, p in alive:
                p.send_signal(sig)
            for _, p in alive:
                try:
                    p.wait(wait)
                except subprocess.TimeoutExpired:
                    pass


async def wait_http(url: str, procs: Processes, limit_s: float = 60) -> None:
    """Wait until `url` answers below 500, while every child keeps running."""
    deadline = time.monotonic() + limit_s
    async with httpx.AsyncClient() as c:
        while time.monotonic() < deadline:
            procs.check()
            try:
                if (await c.get(url, timeout=1)).status_code < 500:
                    return
            except httpx.HTTPError:
                pass
            await asyncio.sleep(0.1)
    raise RuntimeError(f"{url} did not answer within {limit_s:.0f} s")


async def serve_until_stopped(procs: Processes) -> None:
    """Keep the children running until SIGINT or SIGTERM (or one of them exits: RuntimeError)."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    while not stop.is_set():
        procs.check()
        try:
            await asyncio.wait_for(stop.wait(), 1.0)
        except TimeoutError:
            pass

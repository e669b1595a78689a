"""The Janus media path: Streaming-plugin mountpoints per asset over Janus's HTTP API.

The paper's handshake (§2.2.2): when the asset asks where to stream (`POST .../video/rtp`), the
server creates a mountpoint for it from its camera description with `port: 0`, Janus picks the
RTP port and says which, and the asset sends plain RTP (VP8) there. Viewers are brokered to the
mountpoint: Janus 1.1's Streaming plugin always makes the SDP offer (client offers came with
Janus 1.2, meetecho/janus-gateway#3199), so on this path `POST .../whep` carries no body and
answers Janus's offer, and the viewer `PATCH`es its answer. Nothing is transcoded: Janus forwards
the asset's packets. Janus restarting is noticed by the event long-poll (the session is gone) and
the session and every mountpoint this process knows are made again.

A mountpoint outlives its replica: its id comes from the asset's, its `metadata` holds the camera
and when it was made, and another replica (restarted, or given the asset by the proxy's hash)
adopts it as it is, RTP port and viewers kept, instead of destroying and making it again.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
import uuid
from collections.abc import Callable
from typing import Any

import httpx

from server.kit.errors import Conflict, NotFound, Unprocessable
from server.video.camera import CameraDescription
from server.video.errors import GatewayUnavailable, ViewerLimit
from server.video.gateway import Negotiated, RtpTarget, StreamStatus

log = logging.getLogger(__name__)

PAYLOAD_TYPE = 96
LIVE_AGE_MS = 3000  # a mountpoint whose last packet is older than this is offline
EVENT_TIMEOUT_S = 10.0
Mount = tuple[int, int, CameraDescription, float]  # mountpoint id, RTP port, camera, made (Unix s)


class JanusError(Exception):
    """Janus answered an error (its code and reason)."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(f"Janus error {code}: {reason}")
        self.code = code


def mountpoint_id(asset_id: uuid.UUID) -> int:
    """A stable numeric mountpoint id for an asset (48 bits: exact in JSON numbers)."""
    return int.from_bytes(asset_id.bytes[:6], "big")


class JanusClient:
    """The parts of Janus's HTTP API (core and Streaming plugin) this path uses."""

    def __init__(self, url: str) -> None:
        self.url = url.rstrip("/")
        self.http = httpx.AsyncClient(timeout=httpx.Timeout(10.0, read=40.0))

    async def post(self, path: str, body: dict[str, Any]) -> dict[str, Any]:
        """One request; raises JanusError on an error answer, GatewayUnavailable when unreachable."""
        body = {**body, "transaction": uuid.uuid4().hex}
        try:
            r = await self.http.post(f"{self.url}{path}", json=body)
            data: dict[str, Any] = r.json()
        except (httpx.HTTPError, ValueError) as err:
            raise GatewayUnavailable(f"Janus at {self.url} did not answer: {err}") from err
        if data.get("janus") == "error":
            raise JanusError(int(data["error"]["code"]), str(data["error"]["reason"]))
        plugin_error = (data.get("plugindata") or {}).get("data", {}).get("error_code")
        if plugin_error:
            raise JanusError(int(plugin_error), str(data["plugindata"]["data"].get("error", "")))
        return data

    async def events(self, session: int) -> list[dict[str, Any]]:
        """Long-poll the session's events (up to 30 s)."""
        try:
            r = await self.http.get(f"{self.url}/{session}", params={"maxev": 10})
            data = r.json()
        except (httpx.HTTPError, ValueError) as err:
            raise GatewayUnavailable(f"Janus at {self.url} did not answer: {err}") from err
        if isinstance(data, dict):
            if data.get("janus") == "error":
                raise JanusError(int(data["error"]["code"]), str(data["error"]["reason"]))
            return [] if data.get("janus") == "keepalive" else [data]
        return list(data)

    async def info(self) -> dict[str, Any]:
        """Janus's `GET /info` (its version and plugins): raises when Janus does not answer."""
        r = await self.http.get(f"{self.url}/info", timeout=5.0)
        r.raise_for_status()
        data: dict[str, Any] = r.json()
        if data.get("janus") != "server_info":
            raise GatewayUnavailable(f"Janus at {self.url} answered {data.get('janus')!r} to /info")
        return data

    async def close(self) -> None:
        """Close the HTTP client."""
        await self.http.aclose()


class JanusGateway:
    """The Janus media path (`MediaGateway`)."""

    name = "janus"
    viewer_offers = False  # Janus makes the offer; viewers answer (see the module docstring)

    def __init__(self, url: str, rtp_host: str) -> None:
        self.client = JanusClient(url)
        self.rtp_host = rtp_host
        self._session: int | None = None
        self._admin: int | None = None
        self._lock = asyncio.Lock()
        self._poller: asyncio.Task[None] | None = None
        self._inboxes: dict[int, asyncio.Queue[dict[str, Any]]] = {}
        self._mounts: dict[uuid.UUID, Mount] = {}
        self._viewers: dict[uuid.UUID, tuple[uuid.UUID, int]] = {}
        self._on_end: dict[uuid.UUID, Callable[[], None]] = {}  # per viewer: called once it ends

    async def ping(self) -> None:
        """Readiness (`/api/ready`): Janus answers its HTTP API."""
        await self.client.info()

    # ---- session and restart detection
    async def _ensure(self) -> tuple[int, int]:
        async with self._lock:
            if self._session is None or self._admin is None:
                session = (await self.client.post("", {"janus": "create"}))["data"]["id"]
                admin = await self._attach(session)
                self._session, self._admin = session, admin
                if self._poller is None or self._poller.done():
                    self._poller = asyncio.create_task(self._poll(), name="janus-events")
                for asset_id, (_, _, camera, _) in list(self._mounts.items()):
                    await self._create_mount(session, admin, asset_id, camera)
            return self._session, self._admin

    async def _attach(self, session: int) -> int:
        body = {"janus": "attach", "plugin": "janus.plugin.streaming"}
        return int((await self.client.post(f"/{session}", body))["data"]["id"])

    async def _poll(self) -> None:
        while True:
            session = self._session
            if session is None:
                return
            try:
                for event in await self.client.events(session):
                    sender = int(event.get("sender", 0))
                    if event.get("janus") == "hangup":
                        await self._reap(sender)  # the viewer's peer went away
                        continue
                    inbox = self._inboxes.get(sender)
                    if inbox is not None:
                        inbox.put_nowait(event)
            except (JanusError, GatewayUnavailable) as err:
                log.warning("Janus session lost (%s); making it and the mountpoints again", err)
                self._session = self._admin = None
                for viewer_id in list(self._viewers):
                    self._ended(viewer_id)
                self._viewers.clear()
                self._inboxes.clear()
                await asyncio.sleep(1.0)
                with contextlib.suppress(JanusError, GatewayUnavailable):
                    await self._ensure()

    async def _request(self, body: dict[str, Any]) -> dict[str, Any]:
        session, admin = await self._ensure()
        data = await self.client.post(f"/{session}/{admin}", {"janus": "message", "body": body})
        return dict(data["plugindata"]["data"])

    # ---- mountpoints (the paper's handshake)
    async def _create_mount(
        self, session: int, admin: int, asset_id: uuid.UUID, camera: CameraDescription
    ) -> int:
        mid = mountpoint_id(asset_id)
        made = time.time()
        body = {
            "request": "create",
            "type": "rtp",
            "id": mid,
            "description": f"asset {asset_id}",
            "metadata": json.dumps({"camera": camera.model_dump(), "made": made}),
            "media": [
                {"type": "video", "mid": "v", "port": 0, "pt": PAYLOAD_TYPE, "codec": camera.codec}
            ],
        }
        path = f"/{session}/{admin}"
        try:
            data = await self.client.post(path, {"janus": "message", "body": body})
        except JanusError as err:
            if err.code != 456:  # not "already exists" (another replica made it, or a restart)
                raise
            destroy = {"request": "destroy", "id": mid}
            await self.client.post(path, {"janus": "message", "body": destroy})
            data = await self.client.post(path, {"janus": "message", "body": body})
        port = int(data["plugindata"]["data"]["stream"]["ports"][0]["port"])
        self._mounts[asset_id] = (mid, port, camera, made)
        log.info("Janus mountpoint %d for asset %s on RTP port %d", mid, asset_id, port)
        return port

    async def rtp_target(self, asset_id: uuid.UUID, camera: CameraDescription) -> RtpTarget:
        """Where the asset sends its RTP: the mountpoint's port (made when missing)."""
        session, admin = await self._ensure()
        known = await self._mount(asset_id)
        if known is not None and known[2] == camera:
            port = known[1]
        else:
            try:
                port = await self._create_mount(session, admin, asset_id, camera)
            except JanusError as err:  # its configuration refuses ours: say so, not a 500
                log.error("Janus refused a mountpoint for asset %s: %s", asset_id, err)
                raise GatewayUnavailable(f"the media gateway refused the stream: {err}") from err
        return RtpTarget(self.rtp_host, port, PAYLOAD_TYPE, camera.codec)

    async def publish(
        self,
        asset_id: uuid.UUID,
        offer: str,
        camera: CameraDescription,
        on_end: Callable[[], None] | None = None,
    ) -> Negotiated:
        """No WHIP on this path: the asset sends RTP to the mountpoint."""
        raise Conflict(
            "this server's media path is Janus: ask POST .../video/rtp where to send RTP",
            code="use_rtp",
        )

    async def unpublish(self, asset_id: uuid.UUID, session_id: uuid.UUID) -> None:
        """No WHIP publication exists on this path."""
        raise NotFound("no such publication of this asset")

    # ---- viewers
    async def _info(self, asset_id: uuid.UUID) -> dict[str, Any] | None:
        """Janus's `info` of the asset's mountpoint; None when there is none."""
        try:
            data = await self._request({"request": "info", "id": mountpoint_id(asset_id)})
        except JanusError:
            return None
        return dict(data.get("info") or {})

    async def _mount(self, asset_id: uuid.UUID) -> Mount | None:
        """The asset's mountpoint as this process knows it, else as Janus has it (adopted)."""
        known = self._mounts.get(asset_id)
        return known if known is not None else self._adopt(asset_id, await self._info(asset_id))

    def _adopt(self, asset_id: uuid.UUID, info: dict[str, Any] | None) -> Mount | None:
        """The mountpoint Janus describes in `info` (port; the camera and time of making its
        metadata says, whichever replica made it), remembered; None when it is not one of ours."""
        if not info:
            return None
        try:
            meta = json.loads(str(info.get("metadata") or ""))
            port, made = int(info["media"][0]["port"]), float(meta["made"])
            mount = (
                mountpoint_id(asset_id),
                port,
                CameraDescription.model_validate(meta["camera"]),
                made,
            )
        except (ValueError, KeyError, IndexError, TypeError):
            return None  # from before the metadata, or not ours: made again when the UAV asks
        if self._mounts.get(asset_id) != mount:
            log.info("Janus mountpoint %d of asset %s on RTP port %d", mount[0], asset_id, port)
        self._mounts[asset_id] = mount
        return mount

    def _ended(self, viewer_id: uuid.UUID) -> None:
        on_end = self._on_end.pop(viewer_id, None)
        if on_end is not None:
            on_end()

    async def view(
        self,
        asset_id: uuid.UUID,
        offer: str,
        max_viewers: int,
        on_end: Callable[[], None] | None = None,
    ) -> Negotiated:
        """Attach a viewer handle, `watch` the mountpoint; answers Janus's offer."""
        if offer.strip():
            raise Unprocessable(
                "on the Janus path the server makes the offer: POST an empty body, then PATCH "
                "the answer (application/sdp) to the Location",
                code="offer_not_accepted",
            )
        info = await self._info(asset_id)
        known = self._adopt(asset_id, info) or self._mounts.get(asset_id)
        if known is None:
            raise Conflict("the asset has not started streaming yet", code="stream_offline")
        if info is not None and int(info.get("viewers", 0)) >= max_viewers:
            raise ViewerLimit(f"this stream has its {max_viewers} viewers", retry_after_s=5)
        session, _ = await self._ensure()
        handle = await self._attach(session)
        inbox: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self._inboxes[handle] = inbox
        body = {"janus": "message", "body": {"request": "watch", "id": known[0]}}
        await self.client.post(f"/{session}/{handle}", body)
        event = await self._wait(inbox, lambda e: "jsep" in e)
        viewer_id = uuid.uuid4()
        self._viewers[viewer_id] = (asset_id, handle)
        if on_end is not None:
            self._on_end[viewer_id] = on_end
        return Negotiated(viewer_id, str(event["jsep"]["sdp"]), kind="offer")

    async def _wait(self, inbox: asyncio.Queue[dict[str, Any]], match: Any) -> dict[str, Any]:
        try:
            async with asyncio.timeout(EVENT_TIMEOUT_S):
                while True:
                    event = await inbox.get()
                    error = (event.get("plugindata") or {}).get("data", {}).get("error")
                    if error:
                        raise GatewayUnavailable(f"Janus refused: {error}")
                    if match(event):
                        return event
        except TimeoutError as err:
            raise GatewayUnavailable("Janus did not answer in time") from err

    async def _reap(self, handle: int) -> None:
        """Forget and detach a viewer handle whose peer Janus hung up."""
        for viewer_id, (_, h) in list(self._viewers.items()):
            if h == handle:
                del self._viewers[viewer_id]
                self._ended(viewer_id)
                self._inboxes.pop(handle, None)
                if self._session is not None:
                    with contextlib.suppress(JanusError, GatewayUnavailable):
                        await self.client.post(f"/{self._session}/{handle}", {"janus": "detach"})

    def _viewer(self, asset_id: uuid.UUID, session_id: uuid.UUID) -> int:
        found = self._viewers.get(session_id)
        if found is None or found[0] != asset_id:
            raise NotFound("no such viewer session of this asset")
        return found[1]

    async def answer(self, asset_id: uuid.UUID, session_id: uuid.UUID, sdp: str) -> None:
        """The viewer's SDP answer to Janus's offer: `start` the stream."""
        handle = self._viewer(asset_id, session_id)
        session, _ = await self._ensure()
        body = {
            "janus": "message",
            "body": {"request": "start"},
            "jsep": {"type": "answer", "sdp": sdp},
        }
        await self.client.post(f"/{session}/{handle}", body)
        inbox = self._inboxes[handle]
        await self._wait(inbox, lambda e: "result" in (e.get("plugindata") or {}).get("data", {}))

    async def trickle(self, asset_id: uuid.UUID, session_id: uuid.UUID, fragment: str) -> None:
        """The viewer's trickled candidates, handed to Janus."""
        handle = self._viewer(asset_id, session_id)
        session, _ = await self._ensure()
        for line in fragment.splitlines():
            if line.startswith("a=candidate:"):
                candidate = {"candidate": line[2:].strip(), "sdpMid": "v", "sdpMLineIndex": 0}
            elif line.startswith("a=end-of-candidates"):
                candidate = {"completed": True}
            else:
                continue
            await self.client.post(
                f"/{session}/{handle}", {"janus": "trickle", "candidate": candidate}
            )

    async def stop(self, asset_id: uuid.UUID, session_id: uuid.UUID) -> None:
        """Detach the viewer's handle (Janus hangs up its peer)."""
        handle = self._viewer(asset_id, session_id)
        del self._viewers[session_id]
        self._ended(session_id)
        self._inboxes.pop(handle, None)
        if self._session is not None:
            with contextlib.suppress(JanusError, GatewayUnavailable):
                await self.client.post(f"/{self._session}/{handle}", {"janus": "detach"})

    async def status(self, asset_id: uuid.UUID) -> StreamStatus:
        """Live when the mountpoint got media in the last LIVE_AGE_MS; viewers as Janus counts.

        Janus's `age_ms` counts from the mountpoint's creation until a first packet arrives, so a
        young mountpoint's age is not yet evidence of media: it must be clearly below its life."""
        info = await self._info(asset_id)
        known = self._adopt(asset_id, info) or self._mounts.get(asset_id)
        if info is None or known is None:
            return StreamStatus(live=False, viewers=0)
        life_ms = (time.time() - known[3]) * 1000
        ages = [m.get("age_ms") for m in info.get("media", []) if m.get("age_ms") is not None]
        live = bool(ages) and min(ages) < min(LIVE_AGE_MS, life_ms - 500)
        return StreamStatus(live=live, viewers=int(info.get("viewers", 0)))

    async def close(self) -> None:
        """Stop polling and end the session (mountpoints stay: other replicas may serve them)."""
        if self._poller is not None:
            self._poller.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._poller
        session, self._session = self._session, None
        if session is not None:
            with contextlib.suppress(JanusError, GatewayUnavailable):
                await self.client.post(f"/{session}", {"janus": "destroy"})
        await self.client.close()

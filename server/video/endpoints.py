"""HTTP routes of live video: the stream's description, WHEP for viewers, WHIP for the asset."""

from __future__ import annotations

import uuid
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request, Response
from fastapi.responses import FileResponse

from server.deps import CurrentPrincipal, ServicesDep, UoW, Viewer
from server.kit.errors import Conflict, Forbidden, NotFound
from server.kit.openapi import errors
from server.kit.paging import PAGED, Paging, page_of
from server.kit.principal import Principal
from server.video.errors import GatewayUnavailable, UnsupportedMediaType, ViewerLimit
from server.video.gateway import MediaGateway
from server.video.schemas import RecordingOut, RtpTargetOut, VideoOut
from server.video.service import VideoService, check_sdp, whep_path, whip_path

router = APIRouter(tags=["video"])

SDP = "application/sdp"
TRICKLE = "application/trickle-ice-sdpfrag"


def _gateway(services: ServicesDep) -> MediaGateway:
    if services.video is None:
        raise NotFound("live video is not enabled on this server", code="video_disabled")
    return services.video  # type: ignore[no-any-return]


def _build(uow: UoW, principal: Principal, services: ServicesDep) -> VideoService:
    return VideoService(uow, principal, services.settings, _gateway(services), services.hub)


def _viewer_service(uow: UoW, principal: Viewer, services: ServicesDep) -> VideoService:
    return _build(uow, principal, services)


def _publisher_service(
    uow: UoW, principal: CurrentPrincipal, services: ServicesDep
) -> VideoService:
    return _build(uow, principal, services)


Video = Annotated[VideoService, Depends(_viewer_service)]
Publisher = Annotated[VideoService, Depends(_publisher_service)]


def _content_type(request: Request) -> str:
    return request.headers.get("content-type", "").split(";")[0].strip().lower()


async def _body(request: Request, *content_types: str) -> bytes:
    got = _content_type(request)
    if got not in content_types:
        wanted = " or ".join(content_types)
        raise UnsupportedMediaType(f"send {wanted}, not {got or 'no content type'}")
    return await request.body()


def _sdp_body(description: str) -> dict[str, Any]:
    return {
        "requestBody": {
            "required": True,
            "description": description,
            "content": {SDP: {"schema": {"type": "string"}}},
        }
    }


_ANSWER: dict[int | str, dict[str, Any]] = {
    **errors(UnsupportedMediaType),
    201: {
        "description": "the SDP answer; `Location` names the session",
        "content": {SDP: {"schema": {"type": "string"}}},
        "headers": {"Location": {"schema": {"type": "string"}}},
    },
}


@router.get("/api/v1/assets/{asset_id}/video", response_model=VideoOut)
async def describe_video(asset_id: uuid.UUID, video: Video) -> VideoOut:
    """The asset's stream (state, codec, size, fps, viewers, path) and ICE servers to watch it."""
    return await video.describe(asset_id)


@router.post(
    "/api/v1/assets/{asset_id}/video/whep",
    status_code=201,
    response_class=Response,
    responses={**_ANSWER, **errors(Conflict, ViewerLimit, GatewayUnavailable)},
    openapi_extra=_sdp_body("the viewer's SDP offer (receive-only video)"),
)
async def whep_offer(asset_id: uuid.UUID, request: Request, video: Video) -> Response:
    """WHEP: open a viewer session from an SDP offer; answers the SDP answer (Janus path: an
    empty body, answered with Janus's offer)."""
    await video.require_stream(asset_id)  # another organisation's asset is 404 whatever the body
    offer = check_sdp(await _body(request, SDP), allow_empty=True)
    session = await video.view(asset_id, offer)
    return Response(
        content=session.answer,
        status_code=201,
        media_type=SDP,
        headers={"Location": f"{whep_path(asset_id)}/{session.session_id}"},
    )


@router.patch(
    "/api/v1/assets/{asset_id}/video/whep/{session_id}",
    status_code=204,
    response_class=Response,
    responses=errors(UnsupportedMediaType, Conflict, GatewayUnavailable),
    openapi_extra={
        "requestBody": {
            "required": True,
            "content": {
                TRICKLE: {"schema": {"type": "string"}},
                SDP: {"schema": {"type": "string"}},
            },
        }
    },
)
async def whep_patch(
    asset_id: uuid.UUID, session_id: uuid.UUID, request: Request, video: Video
) -> Response:
    """WHEP trickle ICE (an SDP fragment of candidates), or on the Janus path the viewer's SDP
    answer to the offer the POST returned."""
    await video.require_stream(asset_id)
    body = await _body(request, TRICKLE, SDP)
    if _content_type(request) == SDP:
        await video.answer(asset_id, session_id, check_sdp(body))
    else:
        await video.trickle(asset_id, session_id, body.decode("utf-8", errors="replace"))
    return Response(status_code=204)


@router.delete(
    "/api/v1/assets/{asset_id}/video/whep/{session_id}", status_code=204, response_class=Response
)
async def whep_stop(asset_id: uuid.UUID, session_id: uuid.UUID, video: Video) -> Response:
    """WHEP: end a viewer session."""
    await video.stop(asset_id, session_id)
    return Response(status_code=204)


@router.post(
    "/api/v1/assets/{asset_id}/video/whip",
    status_code=201,
    response_class=Response,
    responses={**_ANSWER, **errors(Forbidden, Conflict)},
    openapi_extra=_sdp_body("the asset's SDP offer (send-only VP8 video)"),
)
async def whip_offer(asset_id: uuid.UUID, request: Request, video: Publisher) -> Response:
    """WHIP: the asset publishes its camera (asset sessions only, its own asset only)."""
    await video.require_publisher(asset_id)
    offer = check_sdp(await _body(request, SDP))
    session = await video.publish(asset_id, offer)
    return Response(
        content=session.answer,
        status_code=201,
        media_type=SDP,
        headers={"Location": f"{whip_path(asset_id)}/{session.session_id}"},
    )


@router.post(
    "/api/v1/assets/{asset_id}/video/rtp",
    response_model=RtpTargetOut,
    responses=errors(Forbidden, Conflict, GatewayUnavailable),
)
async def rtp_target(asset_id: uuid.UUID, video: Publisher) -> RtpTargetOut:
    """Janus path: where the asset sends its RTP (a mountpoint made from its camera description,
    on the port Janus chose) — asset sessions only, its own asset only."""
    return await video.rtp_target(asset_id)


@router.delete(
    "/api/v1/assets/{asset_id}/video/whip/{session_id}",
    status_code=204,
    response_class=Response,
    responses=errors(Forbidden),
)
async def whip_stop(asset_id: uuid.UUID, session_id: uuid.UUID, video: Publisher) -> Response:
    """WHIP: the asset ends its publication."""
    await video.unpublish(asset_id, session_id)
    return Response(status_code=204)


@router.get(
    "/api/v1/assets/{asset_id}/video/recordings",
    response_model=list[RecordingOut],
    responses=PAGED,
)
async def list_recordings(asset_id: uuid.UUID, video: Video, pages: Paging) -> list[RecordingOut]:
    """The asset's recorded segments, newest first (empty when recording is off)."""
    found = page_of(await video.recordings(asset_id), pages.page)
    pages.respond(found.total)
    return found.items


@router.get(
    "/api/v1/assets/{asset_id}/video/recordings/{name}",
    response_class=FileResponse,
    responses={
        200: {
            "content": {"video/webm": {}, "application/jsonl": {}},
            "description": "a segment, or its frame times",
        }
    },
)
async def get_recording(asset_id: uuid.UUID, name: str, video: Video) -> FileResponse:
    """One recorded segment (`.webm`) or its frame times (`.times.jsonl`)."""
    path = await video.recording_file(asset_id, name)
    media = "video/webm" if name.endswith(".webm") else "application/jsonl"
    return FileResponse(path, media_type=media, filename=name)

"""The REST API's request and response bodies (the shapes ``/openapi.json`` publishes)."""

from __future__ import annotations

from dataclasses import asdict
from typing import Literal

from pydantic import BaseModel, Field

from .store import SessionInfo


class SessionModel(BaseModel):
    session_id: str
    device_id: str
    mode: str = Field(description="'frames' (the cloud stitches) or 'pages' (the glasses stitch)")
    sensor: tuple[int, int] = Field(description="sensor (width, height) in pixels")
    fovea: tuple[int, int] = Field(description="foveal window (height, width) in pixels")
    created_s: float = Field(description="UNIX time of the first hello")
    updated_s: float = Field(description="UNIX time of the last hello or stored message")
    last_seq: int = Field(description="highest seq durably stored, -1 if none")
    frames: int
    pages: int | None = Field(description="pages the glasses sent (mode 'pages'); null in mode 'frames', whose pages "
                                          "the cloud stitches as frames arrive: GET /v1/sessions/{id}/pages lists them")

    @classmethod
    def of(cls, info: SessionInfo) -> SessionModel:
        return cls(**{**asdict(info), "pages": info.pages if info.mode == "pages" else None})


class AskRequest(BaseModel):
    question: str = Field("what does this say", max_length=2000, description="what the wearer asked")


class LineModel(BaseModel):
    text: str
    box: tuple[int, int, int, int] | None = Field(None, description="x0, y0, x1, y1 in page pixels")
    confidence: float | None = Field(None, description="probability the line reads right (calibrated; a remote engine's own score)")
    status: Literal["read", "unclear"] = Field("read", description="unclear: too unsure to say; the spoken answer does not guess at it")
    reasons: list[str] = Field([], description="what would help an unclear line: glasses_busy, too_dark, too_much_motion, too_small, look_again")
    evidence: dict[str, float] = Field({}, description="what the confidence was judged from")


class AskResponse(BaseModel):
    text: str = Field(description="the text read from the page, lines top to bottom (unclear lines too: `lines` marks "
                      "them, and the spoken answer does not say them)")
    backend: str = Field(description="the OCR engine that read it")
    page_id: str = Field(description="which page: page-<id> (glasses) or stitched-<page>-v<version>")
    page: int | None = Field(None, description="the page read (stitched sessions): 0 = the session's first")
    version: int | None = Field(None, description="the page's version (frames stitched into it) that was read")
    lines_read: int | None = Field(None, description="lines OCR read for this version; the others had not changed")
    frames_pending: bool = Field(False, description="frames stored before the question were still being stitched")
    latency_ms: float = Field(description="time from the question to the answer")
    lines: list[LineModel]
    unclear_lines: int = Field(0, description="lines too unsure to say")
    reasons: list[str] = Field([], description="what would help the unclear lines, most common first")
    spoken: str = Field("", description="what the spoken answer says: the lines read, the unclear ones as such, and what would help "
                        "(\"the quick fox / Two lines unclear. / Please stop moving.\")")
    question: str
    truncated: bool = Field(False, description="the engine stopped early (token limit); text is incomplete")


class PageModel(BaseModel):
    index: int = Field(description="page number, 0 = the session's first")
    version: int = Field(description="frames stitched into it so far")
    first_seq: int
    last_seq: int
    started_by: str = Field(description="first, break (the glasses said so), lost (registration lost), size")
    finished: bool = Field(description="a later page has started; this one no longer changes")


class Health(BaseModel):
    status: str
    checks: dict[str, bool] = {}

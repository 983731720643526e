"""Live pages through a real uvicorn: pages grow as frames arrive, a session is a sequence of
pages, unchanged lines are not read again, updates are pushed, restarts rebuild the same pages."""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

import httpx
import pytest
from page_readings import LINES, reading_frames
from websockets.asyncio.client import connect

from darkread.cloud.app import expire_sessions
from darkread.cloud.ocr.rapid import RapidOcrBackend
from darkread.proto.messages import Ack, Frame, Hello, NewPage, Welcome, decode, encode

API_KEY = "test-key-7f3a"
AUTH = {"X-API-Key": API_KEY}
OTHER_LINES = ["a second page of text comes", "after the first one was read", "by the same pair of glasses"]


def stream(server: Any, session_id: str, messages: list[Frame | NewPage]) -> Welcome:
    async def run() -> Welcome:
        async with connect(server.ws_url, additional_headers=AUTH) as ws:
            await ws.send(encode(Hello(device_id="g", session_id=session_id, mode="frames", sensor=(1280, 720), fovea=(100, 200))))
            welcome = decode(await ws.recv(), max_bytes=1 << 20)
            assert isinstance(welcome, Welcome)
            for message in messages:
                await ws.send(encode(message))
            acks = [decode(await ws.recv(), max_bytes=1 << 20) for _ in messages]
            assert acks[-1] == Ack(seq=messages[-1].seq)
            return welcome

    return asyncio.run(run())


def two_readings(explicit_break: bool) -> list[Frame | NewPage]:
    first = reading_frames(lines=LINES)
    t0 = first[-1].t_us + 200_000
    mark = [NewPage(seq=len(first), t_us=t0)] if explicit_break else []
    second = reading_frames(seed=1, lines=OTHER_LINES, first_seq=len(first) + len(mark), t0_us=t0)
    return [*first, *mark, *second]


@pytest.mark.parametrize("explicit_break", [False, True], ids=["registration-lost", "new-page-message"])
def test_two_pages_one_after_the_other_are_two_pages_each_read_right(
    make_settings: Any, run_server: Any, explicit_break: bool
) -> None:
    messages = two_readings(explicit_break)
    with run_server(make_settings(), ocr=RapidOcrBackend()) as server:
        welcome = stream(server, "two", messages)
        assert welcome.features == ("new_page",)
        with httpx.Client(base_url=server.url, headers=AUTH, timeout=60) as http:
            current = http.post("/v1/sessions/two/ask").json()
            first = http.post("/v1/sessions/two/ask", params={"page": 0}).json()
            pages = http.get("/v1/sessions/two/pages").json()
            missing = http.post("/v1/sessions/two/ask", params={"page": 7})
            png = http.get("/v1/sessions/two/page.png", params={"page": 0})
    assert [p["index"] for p in pages] == [0, 1]
    assert pages[1]["started_by"] == ("break" if explicit_break else "lost") and pages[0]["finished"]
    assert first["page"] == 0 and first["text"].split("\n") == LINES
    assert current["page"] == 1 and current["text"].split("\n") == OTHER_LINES
    assert current["version"] == pages[1]["version"] and current["page_id"] == f"stitched-1-v{current['version']}"
    assert missing.status_code == 409 and "pages 0-1" in missing.json()["detail"]
    assert png.status_code == 200 and png.headers["X-Page"] == "0"


def test_a_restart_rebuilds_the_same_pages_and_answers(make_settings: Any, run_server: Any) -> None:
    settings = make_settings()
    with run_server(settings, ocr=RapidOcrBackend()) as server:
        stream(server, "keep", two_readings(explicit_break=False))
        with httpx.Client(base_url=server.url, headers=AUTH, timeout=60) as http:
            before = [http.post("/v1/sessions/keep/ask", params={"page": i}).json() for i in (0, 1)]
            again = http.post("/v1/sessions/keep/ask", params={"page": 1}).json()
    assert {**again, "latency_ms": 0} == {**before[1], "latency_ms": 0}  # the same version: the same reading
    with run_server(settings, ocr=RapidOcrBackend()) as server:
        with httpx.Client(base_url=server.url, headers=AUTH, timeout=60) as http:
            after = [http.post("/v1/sessions/keep/ask", params={"page": i}).json() for i in (0, 1)]
            assert http.delete("/v1/sessions/keep").status_code == 204
            assert http.get("/v1/sessions/keep/pages").status_code == 404
            assert http.post("/v1/sessions/keep/ask").status_code == 404
        assert server.context.pages.live_sessions == 0
        assert asyncio.run(server.context.store.frames("keep")) == []
    for old, new in zip(before, after):
        assert (new["page"], new["version"], new["text"]) == (old["page"], old["version"], old["text"])


def test_only_lines_that_changed_are_read_again(make_settings: Any, run_server: Any) -> None:
    lines = [*LINES, *OTHER_LINES]
    frames = reading_frames(lines=lines)
    fourth_line = next(i for i, f in enumerate(frames) if f.gaze_px[1] > frames[0].gaze_px[1] + 85)
    with run_server(make_settings(), ocr=RapidOcrBackend()) as server:
        stream(server, "grow", frames[:fourth_line])
        with httpx.Client(base_url=server.url, headers=AUTH, timeout=60) as http:
            early = http.post("/v1/sessions/grow/ask").json()
            stream(server, "grow", frames[fourth_line:])
            late = http.post("/v1/sessions/grow/ask").json()
    assert early["text"].split("\n")[:3] == lines[:3] and early["lines_read"] == len(early["lines"])
    assert late["text"].split("\n") == lines and late["version"] > early["version"]
    assert late["lines_read"] < len(lines)  # the first lines did not change: not read again
    assert late["lines"][0]["text"] == early["lines"][0]["text"]


def test_page_updates_are_pushed_while_the_wearer_reads(server: Any) -> None:
    frames = reading_frames()
    stream(server, "live", frames[:10])
    events: list[dict[str, Any]] = []

    def listen() -> None:
        with httpx.Client(base_url=server.url, headers=AUTH, timeout=30) as http:
            with http.stream("GET", "/v1/sessions/live/events") as response:
                assert response.headers["content-type"].startswith("text/event-stream")
                kind = None
                for line in response.iter_lines():
                    if line.startswith("event: "):
                        kind = line[7:]
                    elif line.startswith("data: ") and kind == "page":
                        events.append(json.loads(line[6:]))
                        if events[-1]["version"] >= 25:
                            return

    async def scenario() -> None:
        listener = asyncio.create_task(asyncio.to_thread(listen))
        await asyncio.sleep(0.5)
        async with connect(server.ws_url, additional_headers=AUTH) as ws:
            await ws.send(encode(Hello(device_id="g", session_id="live", mode="frames", sensor=(1280, 720), fovea=(100, 200))))
            await ws.recv()
            for frame in frames[10:]:
                await ws.send(encode(frame))
                await ws.recv()
                await asyncio.sleep(0.04)  # the glasses' pace
        await asyncio.wait_for(listener, 30)

    asyncio.run(scenario())
    assert len(events) >= 2 and all(e["page"] == 0 for e in events)
    versions = [e["version"] for e in events]
    assert versions == sorted(versions) and versions[-1] >= 25
    assert events[-1]["lines"] and all("text" in line and len(line["box"]) == 4 for line in events[-1]["lines"])
    assert all(line["status"] in ("read", "unclear") for line in events[-1]["lines"])


def test_lines_the_model_is_unsure_of_are_unclear_in_the_answer_and_the_push(
    make_settings: Any, run_server: Any, tmp_path: Any
) -> None:
    """A model that trusts no line (its threshold above any confidence), and takes any disagreement of
    the frames for too dark: every line is unclear, with that reason, in the JSON answer, the push and the spoken words."""
    from darkread.cloud.confidence import load_model

    shipped = load_model()
    doubting = {**{k: getattr(shipped, k) for k in ("mean", "scale", "weights", "intercept", "fast_head_speed", "small_height_px")},
                "features": list(shipped.features), "answer_threshold": 1.01, "dark_ink_solid": 2.0}
    path = tmp_path / "doubting.json"
    path.write_text(json.dumps(doubting))
    with run_server(make_settings(line_confidence_model=path), ocr=RapidOcrBackend()) as server:
        stream(server, "doubt", reading_frames())
        with httpx.Client(base_url=server.url, headers=AUTH, timeout=60) as http:
            answer = http.post("/v1/sessions/doubt/ask").json()
            with http.stream("GET", "/v1/sessions/doubt/events") as response:
                data = next(line for line in response.iter_lines() if line.startswith("data: "))
    assert answer["lines"] and answer["unclear_lines"] == len(answer["lines"])
    assert all(line["status"] == "unclear" and "too_dark" in line["reasons"] for line in answer["lines"]), answer["lines"]
    assert answer["reasons"][0] == "too_dark" and answer["text"].split("\n") == LINES  # the guesses stay in the JSON
    assert LINES[0] not in answer["spoken"] and "The whole page is unclear." in answer["spoken"] and "Please add more light." in answer["spoken"]
    pushed = json.loads(data[6:])["lines"]
    assert pushed and all(line["status"] == "unclear" and line["reasons"] for line in pushed)


def test_idle_sessions_leave_memory_and_expire(make_settings: Any, run_server: Any) -> None:
    with run_server(make_settings(live_idle_s=0.05, session_expire_s=3600)) as server:
        stream(server, "old", reading_frames()[:12])
        with httpx.Client(base_url=server.url, headers=AUTH, timeout=30) as http:
            assert http.get("/v1/sessions/old/pages").json()[0]["index"] == 0
            deadline = time.monotonic() + 10
            while server.context.pages.live_sessions and time.monotonic() < deadline:
                time.sleep(0.05)  # the sweep frees the idle session's pages
            assert server.context.pages.live_sessions == 0
            assert http.get("/v1/sessions/old").json()["frames"] == 12  # the data stays
            server.context.settings.session_expire_s = 1e-6  # the running sweep now deletes it
            deadline = time.monotonic() + 10
            while http.get("/v1/sessions/old").status_code != 404 and time.monotonic() < deadline:
                time.sleep(0.05)
            assert http.get("/v1/sessions/old").status_code == 404
            assert asyncio.run(expire_sessions(server.context)) == []  # nothing left to expire


def test_views_of_glasses_that_shed_work_are_counted_and_their_lines_say_so(make_settings: Any, run_server: Any) -> None:
    """Views made by a live edge falling behind (edge.load) carry the level; the cloud counts them
    (Prometheus) and each line of their page has it as evidence, so the confidence can take it in."""
    from dataclasses import replace

    from darkread.proto.messages import View

    views = []
    for frame in reading_frames(lines=LINES):
        record = frame.record()
        views.append(View.of(replace(record, levels=record.mask, n_levels=2, shed_level=3), seq=frame.seq))
    with run_server(make_settings(), ocr=RapidOcrBackend()) as server:
        stream(server, "starved", views)
        with httpx.Client(base_url=server.url, headers=AUTH, timeout=60) as http:
            answer = http.post("/v1/sessions/starved/ask").json()
            metrics = http.get("/metrics/").text  # (the test key is an admin key)
    assert answer["lines"] and all(line["evidence"]["edge_shed"] == 3.0 for line in answer["lines"])
    assert f'darkread_ws_views_shed_total{{level="3"}} {float(len(views))}' in metrics

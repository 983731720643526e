"""The answer in under a second: how long a question takes while the wearer is still reading, in
sessions of 300, 3,000 and 30,000 stored frames; cloud CPU per second of reading; 20 wearers.

Frames are the shipped sample recording's, made once by a real edge (``darkread read`` in its
default mode, whose answer time is reported too); longer sessions repeat them with shifted seqs
and timestamps. The cloud runs in its own process (``darkread cloud serve``, embedded OCR on one
thread: one core for OCR). For a session of N frames, N - (one recording) are stored before the service starts
(it rebuilds the pages from the store, as after a restart), then the last recording's frames
stream at 1x real time while a question is asked every half second; ``ask_p95_ms_N`` is the
95th percentile of those answers. The reference is the time to read the same page whole from
scratch (stitch every frame, then OCR), as the service did before pages grew as frames arrived.

Cloud CPU per second of reading is measured on a wearer who streams three passes of the
recording at 1x and asks every few seconds (as each of the 20 wearers does), for both kinds of
stream the edge sends: every-window binary frames (``_frames``, ~100-300 a second) and one fused
view per fixation (``_views``, ~5-10 a second); ``cloud_cpu_ms_per_reading_s`` is the kind
``darkread read`` sends by default. The CPU of the ask-every-half-second run is written too
(``cloud_cpu_ms_per_reading_s_asking_2hz``): a question costs a render and the OCR of the lines
that changed, so asking twice a second costs more than the reading itself.

The 20 wearers stream into one instance that reads with one OCR engine per core of the host
(``ocr_threads``, up to 4). Independent wearers start at different moments: wearer i starts
i/20 of an ask period after the first and reads three passes (``wearers_ask_p95_ms_20``). The
same 20 starting in one instant, one pass each, is measured too (``wearers_burst_ask_p95_ms_20``):
every first question, each a whole new page, then arrives within a few milliseconds of the others,
the worst case for the queue.

What reading within the language costs an answer (rapidocr's alphabet mask, the trigram model's
correction of coherent text, each line judged): ``ask_p95_ratio_language`` is the ask p95 on the
300-frame session against a service with ``ocr_language=any`` (every character of the engine,
non-word fixes only); the two run alternately three times each, a fresh service every run, and the
ratio is of their medians (goal <= 1.2): run one after the other, the host's drift between them
was as large as the figure.
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from darkread.cloud.ocr import create_backend
from darkread.cloud.settings import Settings
from darkread.cloud.store import SessionSpec, SqliteStore, StoredFrame
from darkread.core.paths import SAMPLE_RECORDING
from darkread.edge.config import default_infer_mode
from darkread.lab.bench import BenchContext, Figure, cpu_seconds
from darkread.lab.bench.cloud import API_KEY, start_server, stop_server
from darkread.proto.messages import Ack, Frame, Hello, View, Welcome, decode, encode
from darkread.read import read_recording
from darkread.stitch import stitch_page

ASK_EVERY_S = 0.5
WEARERS = 20
WEARER_ASK_EVERY_S = 3.0
WEARER_PASSES = 3  # each wearer reads the recording three times over (about 9 s), as in the CPU figure
# The single-session figures read with one OCR engine (one core for OCR); the 20 wearers share one
# instance that uses the host's cores, one OCR engine each (``ocr_threads``).
ASK_OCR_THREADS = 1
WEARER_OCR_THREADS = max(1, min(4, os.cpu_count() or 1))
HEADERS = {"X-API-Key": API_KEY}


STREAM_KINDS = {"every-window": "frames", "on-change": "views"}  # ``darkread read --infer`` -> figure suffix


def default_infer() -> str:
    """The mode ``darkread read`` uses unless told otherwise (the bench follows it)."""

    return default_infer_mode()


def recorded_frames(ctx: BenchContext, infer: str | None = None) -> tuple[list[StoredFrame], float]:
    """The sample recording's frames (``infer`` mode; None: the default) as the cloud stored them,
    and ``darkread read``'s answer_ms."""

    infer = infer or default_infer()
    out = ctx.scratch / f"read-sample-{infer}"
    result = read_recording(SAMPLE_RECORDING, out_dir=out, infer=infer)
    ctx.notes.append(f"darkread read --demo --infer {infer}: CER {result.cer:.1%}, answer {result.answer_ms:.0f} ms, "
                     f"{result.frames} messages")  # fmt: skip

    async def load() -> list[StoredFrame]:
        store = SqliteStore(out / "cloud")
        try:
            session = (await store.sessions())[0].session_id
            return await store.frames(session, limit=1_000_000)
        finally:
            await store.close()

    return asyncio.run(load()), result.answer_ms


def demo_answer_runs(ctx: BenchContext) -> list[Figure]:
    """``darkread read --demo``'s answer_ms, question to answer: in fresh processes (each starts its
    cloud, whose OCR engine loads while the edge streams: the question must not wait for it) and
    warm (one process reading again and again); the spread of all of them."""


    runs = ctx.runs(5, 3, 1)
    command = [sys.executable, "-m", "darkread", "-q", "read", "--demo", "--json"]
    after_start = [json.loads(subprocess.run(command, capture_output=True, text=True, timeout=600, check=True).stdout)["answer_ms"]
                   for _ in range(runs)]  # fmt: skip
    warm = [read_recording(SAMPLE_RECORDING).answer_ms for _ in range(runs)]
    ctx.notes.append(f"darkread read --demo answer_ms: fresh processes {after_start}, warm {warm}; {_load()}")
    every = after_start + warm
    return [
        Figure("read_demo_answer_ms_after_start_max", max(after_start),
               f"darkread read --demo in a fresh process, worst of {runs}: question to answer [ms]", goal="<= 1000"),
        Figure("read_demo_answer_ms_warm_max", max(warm), f"darkread read --demo warm, worst of {runs} [ms]"),
        Figure("read_demo_answer_spread", max(every) / min(every),
               f"darkread read --demo answer_ms, slowest / fastest of {len(every)} (fresh and warm) [x]",
               reference=f"{min(every):.0f}-{max(every):.0f} ms", goal="<= 2"),
    ]


def repeated(frames: list[StoredFrame], count: int, first_seq: int = 0) -> list[StoredFrame]:
    """``count`` frames: the recording over and over, each pass later in time than the last."""
    span = frames[-1].t_us - frames[0].t_us + 100_000
    out = []
    for i in range(count):
        cycle, frame = divmod(i, len(frames))
        source = frames[frame]
        t_us = source.t_us + cycle * span
        out.append(replace(source, seq=first_seq + i, frame_id=first_seq + i, t_us=t_us))
    return out


def to_wire(frame: StoredFrame) -> bytes:
    """The stored record as the glasses sent it: a fused view with its levels (it may be larger
    than the fovea), or a binary frame."""
    if frame.levels is None:
        return encode(Frame.of(frame, seq=frame.seq, gaze_rad=frame.gaze_rad, events_used=frame.events_used))
    return encode(View.of(frame, seq=frame.seq, gaze_rad=frame.gaze_rad, events_used=frame.events_used))


def preload(data_dir: Path, session_id: str, frames: list[StoredFrame]) -> None:
    async def write() -> None:
        store = SqliteStore(data_dir)
        try:
            await store.open_session(SessionSpec(session_id, "bench", "frames", (1280, 720), (100, 200)))
            for start in range(0, len(frames), 256):
                await asyncio.gather(*(store.add_frame(session_id, f) for f in frames[start : start + 256]))
        finally:
            await store.close()

    asyncio.run(write())


async def stream_and_ask(base: str, session_id: str, frames: list[StoredFrame], ask_every_s: float) -> list[float]:
    """Stream ``frames`` at 1x real time (their t_us) and ask every ``ask_every_s``; answer times (ms)."""
    import httpx
    from websockets.asyncio.client import connect

    url = base.replace("http", "ws") + "/v1/stream"
    latencies: list[float] = []
    done = asyncio.Event()

    async def ask_loop(http: httpx.AsyncClient) -> None:
        while not done.is_set():
            await asyncio.sleep(ask_every_s)
            started = time.perf_counter()
            response = await http.post(f"/v1/sessions/{session_id}/ask")
            if response.status_code == 200:
                latencies.append((time.perf_counter() - started) * 1000)

    async with httpx.AsyncClient(base_url=base, headers=HEADERS, timeout=120) as http:
        async with connect(url, additional_headers=HEADERS, max_size=None, open_timeout=120, ping_interval=None) as ws:
            await ws.send(encode(Hello(device_id="bench", session_id=session_id, mode="frames", sensor=(1280, 720),
                                       fovea=(100, 200))))  # fmt: skip
            welcome = decode(await ws.recv(), max_bytes=1 << 20)
            assert isinstance(welcome, Welcome)  # the service under test answers hello
            asker = asyncio.create_task(ask_loop(http))
            wall0, t0 = time.perf_counter(), frames[0].t_us
            acked = -1

            async def receive() -> None:
                nonlocal acked
                while acked < frames[-1].seq:
                    message = decode(await ws.recv(), max_bytes=1 << 20)
                    if isinstance(message, Ack):
                        acked = message.seq

            receiver = asyncio.create_task(receive())
            for frame in frames:
                delay = (frame.t_us - t0) / 1e6 - (time.perf_counter() - wall0)
                if delay > 0:
                    await asyncio.sleep(delay)
                await ws.send(to_wire(frame))
            await receiver
            done.set()
            await asker
        started = time.perf_counter()
        final = await http.post(f"/v1/sessions/{session_id}/ask")
        final.raise_for_status()
        latencies.append((time.perf_counter() - started) * 1000)
    return latencies


def p95(values: list[float]) -> float:
    return float(np.percentile(values, 95)) if values else float("nan")


async def _wait_rebuilt(base: str, session_id: str, timeout_s: float) -> float:
    """Ask for the pages until the service has stitched everything stored; seconds it took."""
    import httpx

    started = time.perf_counter()
    async with httpx.AsyncClient(base_url=base, headers=HEADERS, timeout=120) as http:
        while time.perf_counter() - started < timeout_s:
            pages = (await http.get(f"/v1/sessions/{session_id}/pages")).json()
            info = (await http.get(f"/v1/sessions/{session_id}")).json()
            if pages and max(p["last_seq"] for p in pages) >= info["last_seq"] - 3:
                break
            await asyncio.sleep(0.1)
    return time.perf_counter() - started


def _server(ctx: BenchContext, name: str, ocr_threads: int = ASK_OCR_THREADS, language: str = "en") -> tuple[subprocess.Popen[bytes], str]:
    """The service in its own process, once /readyz says its OCR engines are loaded."""
    import httpx

    os.environ.update(DARKREAD_ASK_RATE_PER_MIN="1000000", DARKREAD_ASK_BURST="10000",  # asks every 0.5 s
                      DARKREAD_OCR_THREADS=str(ocr_threads), DARKREAD_OCR_LANGUAGE=language)
    process, port = start_server(ctx.scratch / name)
    base = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{base}/readyz", timeout=60).status_code == 200:
                break
        except httpx.HTTPError:
            pass
        time.sleep(0.5)
    return process, base


def _wearers(base: str, frames: list[StoredFrame], stagger_s: float) -> tuple[float, bool]:
    """20 wearers at 1x real time, each asking every few seconds; p95 answer and exactly-once.
    Wearer i starts ``i / 20 * stagger_s`` after the first (0: all at once)."""
    import httpx

    async def one(i: int) -> list[float]:
        await asyncio.sleep(i * stagger_s / WEARERS)
        return await stream_and_ask(base, f"wearer-{i}", frames, WEARER_ASK_EVERY_S)

    async def all_of_them() -> list[list[float]]:
        return await asyncio.gather(*(one(i) for i in range(WEARERS)))

    latencies = [ms for one_wearer in asyncio.run(all_of_them()) for ms in one_wearer]
    with httpx.Client(base_url=base, headers=HEADERS, timeout=60) as http:
        counts = [http.get(f"/v1/sessions/wearer-{i}").json()["frames"] for i in range(WEARERS)]
    return p95(latencies), all(count == len(frames) for count in counts)


def from_scratch_ms(frames: list[StoredFrame]) -> tuple[float, float]:
    """The old way to answer: stitch every stored frame, then read the whole page (ms each)."""

    ocr = create_backend(Settings(_env_file=None))
    ocr.ready()
    started = time.perf_counter()
    page = stitch_page(frames)
    stitched = time.perf_counter()
    ocr.read(page.to_grey())
    return (stitched - started) * 1000, (time.perf_counter() - stitched) * 1000


def reading_cpu(ctx: BenchContext, frames: list[StoredFrame], kind: str) -> tuple[float, float]:
    """Cloud CPU (ms) per second of reading for one wearer streaming three passes of ``frames`` at
    1x and asking every ``WEARER_ASK_EVERY_S``; and the seconds of reading it was measured over."""
    passes = 1 if ctx.smoke else 3
    stream = repeated(frames, passes * len(frames))
    name = f"cpu-{kind}"
    process, base = _server(ctx, name)
    try:
        cpu0 = cpu_seconds(process.pid)
        asyncio.run(stream_and_ask(base, name, stream, WEARER_ASK_EVERY_S))
        asyncio.run(_wait_rebuilt(base, name, timeout_s=600))  # questions do not wait for stitching: the CPU must
        cpu_ms = (cpu_seconds(process.pid) - cpu0) * 1000
    finally:
        stop_server(process)
    reading_s = (stream[-1].t_us - stream[0].t_us) / 1e6
    return cpu_ms / reading_s, reading_s


LANGUAGE_PAIRS = 3  # alternated runs of each service: the host's drift between two runs is not the figure


def _language_ratio(ctx: BenchContext, frames: list[StoredFrame]) -> Figure:
    """The answer's cost of reading within the language: ask p95 on the 300-frame session against a
    service with ``ocr_language=any`` (every character of the engine, non-word fixes only, as before
    the alphabet mask and the language model). The two run alternately, ``LANGUAGE_PAIRS`` times each
    (a fresh service and session every run), and the ratio is of their medians."""
    p95s: dict[str, list[float]] = {"en": [], "any": []}
    answers = 0
    for i in range(1 if ctx.smoke else LANGUAGE_PAIRS):
        for language in ("en", "any"):
            name = f"ask-language-{language}-{i}"
            process, base = _server(ctx, name, language=language)
            try:
                latencies = asyncio.run(stream_and_ask(base, name, frames, ASK_EVERY_S))
            finally:
                stop_server(process)
            p95s[language].append(p95(latencies))
            answers += len(latencies)
    within, anything = float(np.median(p95s["en"])), float(np.median(p95s["any"]))
    runs = ", ".join(f"{a:.0f}/{b:.0f}" for a, b in zip(p95s["en"], p95s["any"]))
    print(f"[bench] ask {len(frames)} frames, en/any p95 alternated: {runs} ms; {_load()}", file=sys.stderr, flush=True)
    return Figure("ask_p95_ratio_language", within / anything,
                  "ask p95 reading within the language (alphabet mask, trigram LM, line judgements) over ocr_language=any",
                  reference=f"medians of {len(p95s['en'])} alternated runs each: {within:.0f} ms against {anything:.0f} ms "
                            f"(en/any per pair: {runs} ms; {answers} answers)", goal="<= 1.2")


def _load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.1f} {five:.1f} {fifteen:.1f}"


def run(ctx: BenchContext) -> list[Figure]:
    default = default_infer()
    frames, demo_answer_ms = recorded_frames(ctx, default)
    stitch_ms, ocr_ms = from_scratch_ms(frames)
    reading_s = (frames[-1].t_us - frames[0].t_us) / 1e6
    figures = [Figure("read_demo_answer_ms", demo_answer_ms, "darkread read --demo: question to answer [ms]",
                      goal="<= 1000")]  # fmt: skip
    figures += demo_answer_runs(ctx)
    per_kind: dict[str, float] = {}
    for infer, kind in STREAM_KINDS.items():
        stream = frames if infer == default else recorded_frames(ctx, infer)[0]
        per_kind[kind], seconds = reading_cpu(ctx, stream, kind)
        rate = len(stream) / ((stream[-1].t_us - stream[0].t_us) / 1e6)
        print(f"[bench] cloud CPU, {kind} ({rate:.0f}/s): {per_kind[kind]:.0f} ms per s of reading over {seconds:.1f} s; "
              f"{_load()}", file=sys.stderr, flush=True)  # fmt: skip
        figures.append(Figure(f"cloud_cpu_ms_per_reading_s_{kind}", per_kind[kind],
                              f"cloud CPU per s of reading, {kind} ({rate:.0f}/s), asking every {WEARER_ASK_EVERY_S:g} s [ms]",
                              reference=_load(), goal="<= 100"))  # fmt: skip
    figures.append(Figure("cloud_cpu_ms_per_reading_s", per_kind[STREAM_KINDS[default]],
                          f"cloud CPU per s of reading, one wearer ({STREAM_KINDS[default]}, darkread read's default) [ms]",
                          reference=f"{len(frames) / reading_s:.0f} {STREAM_KINDS[default]}/s of reading", goal="<= 100"))  # fmt: skip
    sizes = (300,) if ctx.smoke else (300, 3000) if ctx.quick else (300, 3000, 30000)
    for size in sizes:
        name = f"ask-{size}"
        stored = repeated(frames, size)
        live = stored[-len(frames):] if size > len(frames) else stored
        preload(ctx.scratch / name, name, stored[: len(stored) - len(live)])
        process, base = _server(ctx, name)
        try:
            rebuild_s = asyncio.run(_wait_rebuilt(base, name, timeout_s=1800)) if size > len(frames) else 0.0
            cpu0 = cpu_seconds(process.pid)
            latencies = asyncio.run(stream_and_ask(base, name, live, ASK_EVERY_S))
            behind_s = asyncio.run(_wait_rebuilt(base, name, timeout_s=600))  # every frame stitched, its CPU counted
            cpu_ms = (cpu_seconds(process.pid) - cpu0) * 1000
        finally:
            stop_server(process)
        ctx.notes.append(f"ask {size}: {len(latencies)} answers, max {max(latencies):.0f} ms, pages rebuilt from "
                         f"{size - len(live)} stored frames in {rebuild_s:.0f} s, stitching done {behind_s:.1f} s after "
                         f"the last answer; {_load()}")  # fmt: skip
        reference = f"from scratch ~{stitch_ms * size / len(frames) + ocr_ms:.0f} ms (stitch all, then OCR)"
        print(f"[bench] ask {size}: p95 {p95(latencies):.0f} ms over {len(latencies)} answers, {reference}; "
              f"cloud CPU {cpu_ms:.0f} ms for {reading_s:.1f} s of reading", file=sys.stderr, flush=True)  # fmt: skip
        figures.append(Figure(f"ask_p95_ms_{size}", p95(latencies), f"ask while reading, {size} frames stored [ms, p95]",
                              reference=reference, goal="<= 1000"))  # fmt: skip
        if size == sizes[0]:
            figures.append(Figure("cloud_cpu_ms_per_reading_s_asking_2hz", cpu_ms / reading_s,
                                  f"cloud CPU per s of reading, asking every {ASK_EVERY_S:g} s [ms]",
                                  reference=f"asking every {WEARER_ASK_EVERY_S:g} s: "
                                            f"{per_kind[STREAM_KINDS[default]]:.0f}"))  # fmt: skip
    figures.append(_language_ratio(ctx, repeated(frames, sizes[0])))
    passes = 1 if ctx.smoke else WEARER_PASSES
    runs = {  # independent wearers (the figure), and the same wearers all starting in one instant
        "": (repeated(frames, passes * len(frames)), WEARER_ASK_EVERY_S),
        "_burst": (frames, 0.0),
    }
    for suffix, (stream, stagger_s) in runs.items():
        process, base = _server(ctx, f"wearers{suffix}", WEARER_OCR_THREADS)
        try:
            wearers_p95, exactly_once = _wearers(base, stream, stagger_s)
        except Exception as exc:  # a failed stream is a figure (nan), not a crash of the bench
            ctx.notes.append(f"wearers{suffix}: a stream failed ({type(exc).__name__}: {exc}); the host is too busy for {WEARERS}")
            wearers_p95, exactly_once = float("nan"), False
        finally:
            stop_server(process)
        how = (f"starting over {stagger_s:g} s, {passes} passes" if stagger_s else
               "all starting at once, one pass: every first question at the same instant")
        figures.append(Figure(f"wearers{suffix}_ask_p95_ms_{WEARERS}", wearers_p95,
                              f"{WEARERS} wearers at 1x, each asking every {WEARER_ASK_EVERY_S:g} s ({how}), one instance, "
                              f"{WEARER_OCR_THREADS} OCR threads [ms, p95]",
                              reference=_load(), goal="<= 2000" if not suffix else ""))  # fmt: skip
        figures.append(Figure(f"wearers{suffix}_frames_exactly_once_{WEARERS}", float(exactly_once),
                              f"{WEARERS} wearers ({how}): every frame stored exactly once [1 = yes]", goal="1"))  # fmt: skip
    return figures

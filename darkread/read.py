"""``darkread read``: the whole pipeline in one command.

A real edge replays the recording as fast as inference allows into a real cloud service on
127.0.0.1 (a free port, a scratch data directory), the cloud stitches the frames into a page and
reads it with the chosen OCR backend, and the answer comes back over the REST ask endpoint — the
same path the glasses and a user take, only on one machine. The cloud stitches each frame as it
is stored, so once the stream has ended the question is answered from the page already there
(``answer_ms``). The OCR engine loads while the edge streams; if the stream ends first, the
question is asked once the engine is ready, and that wait is its own stage (``ocr_ready``).
"""

from __future__ import annotations

import argparse
import json
import logging
import secrets
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from darkread.cloud.ocr.base import OCR_BACKENDS
from darkread.core.text_metrics import error_rates
from darkread.edge.config import INFER_MODES, default_infer_mode
from darkread.edge.head_motion import KnownHeadMotion

if TYPE_CHECKING:
    from darkread.edge.builder import Edge

logger = logging.getLogger(__name__)

READ_HELP = """\
Read a recording end to end: replay it through the edge (fovea -> voxel -> U-Net -> binary
frames), stream the frames to a cloud service started on 127.0.0.1, stitch them into a page and
read the page with OCR. Prints the text; with --json, one JSON object with the per-stage figures.

When the recording has a text.txt (the printed text), the character and word error rates are
reported too.

Examples:
  darkread read --demo                         the shipped sample recording
  darkread read path/to/recording --json
  darkread read path/to/recording --backend tesseract --out /tmp/read
  darkread read events.raw --gaze-csv gaze.csv --calibration calibration.json
  darkread read --demo --say                   ... and speak the answer (espeak-ng in the cloud)
  darkread read --demo --say-out answer.wav    ... and write the spoken answer to a WAV file
"""


@dataclass
class ReadResult:
    """What one read produced, with figures from every stage."""

    text: str
    backend: str
    recording: str
    events_in: int
    events_foveated: int  # events the edge counted inside the window it had placed
    frames: int
    frames_no_gaze: int
    messages_sent: int
    bytes_sent: int
    raw_bytes: int
    page_png: str
    page_id: str
    lines: list[str]
    seconds: float
    answer_ms: float  # question to answer, once the stream has ended
    stage_seconds: dict[str, float] = field(default_factory=dict)
    reference: str | None = None
    cer: float | None = None
    wer: float | None = None
    speech_wav: str | None = None
    fovea_event_fraction: float | None = None  # inside the window at their own gaze (as ``darkread inspect``)
    answer_lines: list[dict[str, Any]] = field(default_factory=list)  # the answer's lines: text, status, confidence, evidence
    spoken: str = ""  # what the spoken answer says

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def read_recording(
    path: str | Path,
    *,
    backend: str = "local",
    mode: str = "frames",
    model: str | None = None,
    out_dir: str | Path | None = None,
    drain_timeout_s: float = 60.0,
    lexicon: bool = True,
    infer: str | None = None,
    speech_wav: str | Path | None = None,
    known_motion: KnownHeadMotion | None = None,
    gaze_csv: str | Path | None = None,
    calibration: str | Path | None = None,
    prepare_edge: Callable[[Edge], None] | None = None,
) -> ReadResult:
    """Replay ``path`` through a real edge into a real cloud on loopback and ask what it says.

    With ``speech_wav`` the answer is also asked for as speech (``Accept: audio/wav``) and written
    to that WAV file (outside ``out_dir``, it outlives a scratch one). With ``known_motion``
    the edge takes the head's motion from that source (an inertial sensor, or in the lab the simulator's
    truth) instead of measuring it from the events. ``gaze_csv`` and
    ``calibration`` go with a bare ``.raw`` file (or override a recording directory's own).
    ``prepare_edge`` is called with the built edge before it runs (the lab holds it in a state a
    live edge reaches, e.g. a shedding level).
    """
    import httpx
    from pydantic import SecretStr

    from darkread.cloud.app import create_app
    from darkread.cloud.errors import CloudError
    from darkread.cloud.server import serve_in_thread
    from darkread.cloud.settings import Settings
    from darkread.edge.builder import build_edge
    from darkread.edge.config import load_config
    from darkread.edge.daemon import Daemon
    from darkread.edge.errors import RunError
    from darkread.edge.inspect import fovea_event_fraction
    from darkread.edge.io.recording import open_recording
    from darkread.edge.notify import Notifier

    if out_dir is None:  # a scratch directory that does not outlive the read
        with tempfile.TemporaryDirectory(prefix="darkread-read-", ignore_cleanup_errors=True) as scratch:
            result = read_recording(path, backend=backend, mode=mode, model=model, out_dir=scratch,
                                    drain_timeout_s=drain_timeout_s, lexicon=lexicon, infer=infer,
                                    speech_wav=speech_wav, known_motion=known_motion, gaze_csv=gaze_csv,
                                    calibration=calibration, prepare_edge=prepare_edge)
        result.page_png = ""
        return result
    started = time.perf_counter()
    recording = open_recording(path, gaze=str(gaze_csv) if gaze_csv else None,  # fails early, naming any missing file
                               calibration=str(calibration) if calibration else None)
    recording.gaze()  # a broken gaze CSV fails here too, before a cloud starts
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    api_key = secrets.token_urlsafe(16)
    settings = Settings(data_dir=out / "cloud", api_key=SecretStr(api_key), ocr_backend=backend,
                        ocr_lexicon=lexicon, ask_catch_up_s=drain_timeout_s)  # the answer covers every frame
    stages: dict[str, float] = {}
    with serve_in_thread(create_app(settings)) as server:
        stages["cloud_start"] = time.perf_counter() - started
        overrides: dict[str, dict[str, Any]] = {
            "source": {"kind": "replay", "path": str(recording.path if recording.path.is_dir() else recording.raw_path), "speed": 0.0,
                       "gaze_csv": str(recording.gaze_path), "calibration": str(calibration or "")},
            "gaze": {"kind": "recording"},
            "pipeline": {"lossless": True, "infer": infer or default_infer_mode(), **({"model": str(model)} if model else {})},
            "uplink": {"url": server.ws_url, "api_key": api_key, "mode": mode, "spool_dir": str(out / "spool"),
                       "drain_timeout_s": drain_timeout_s},
            "metrics": {"log_every_s": 3600.0},
        }
        t0 = time.perf_counter()
        edge = build_edge(load_config(None, environ={}, overrides=overrides), known_motion=known_motion)
        if prepare_edge is not None:
            prepare_edge(edge)
        daemon = Daemon(edge, Notifier(environ={}), tick_s=0.02, shutdown_timeout_s=drain_timeout_s, handle_signals=False)
        drained = daemon.run() == 0
        stages["edge"] = time.perf_counter() - t0
        if not drained:
            raise RunError(f"the cloud did not acknowledge every frame within {drain_timeout_s:g} s")
        totals = edge.metrics.snapshot().totals
        session_id = edge.uplink.session_id
        headers = {"X-API-Key": api_key}
        with httpx.Client(base_url=server.url, headers=headers, timeout=settings.ocr_timeout_s + 30) as client:
            try:
                # The OCR engine started loading with the cloud, before the edge; on a busy machine the
                # stream can end first. That wait is the engine's start-up, reported apart (stage
                # "ocr_ready"), so answer_ms stays question to answer.
                t0 = time.perf_counter()
                client.get("/readyz")
                stages["ocr_ready"] = time.perf_counter() - t0
                t0 = time.perf_counter()  # the pages grew while the frames arrived: this is the wait for the answer
                answer = client.post(f"/v1/sessions/{session_id}/ask", json={}).raise_for_status().json()
                answer_ms = (time.perf_counter() - t0) * 1000
                page = client.get(f"/v1/sessions/{session_id}/page.png").raise_for_status().content
                spoken = _ask_spoken(client, session_id) if speech_wav is not None else None
            except httpx.HTTPStatusError as exc:
                detail = exc.response.json().get("detail", "") if exc.response.headers.get("content-type", "").startswith(
                    "application/json") else exc.response.text[:200]
                raise CloudError(f"{recording.path}: the page could not be read (HTTP {exc.response.status_code}: "
                                 f"{detail})") from None
        stages["answer"] = answer_ms / 1000
    page_png = out / "page.png"
    page_png.write_bytes(page)
    if speech_wav is not None and spoken is not None:
        Path(speech_wav).parent.mkdir(parents=True, exist_ok=True)
        Path(speech_wav).write_bytes(spoken)
    result = ReadResult(
        text=answer["text"],
        backend=answer["backend"],
        recording=str(recording.path),
        events_in=int(totals["events_in"]),
        events_foveated=int(totals["events_foveated"]),
        frames=int(totals["frames"]),
        frames_no_gaze=int(totals["frames_no_gaze"]),
        messages_sent=int(totals["messages_sent"]),
        bytes_sent=int(totals["bytes_sent"]),
        raw_bytes=recording.raw_path.stat().st_size,
        page_png=str(page_png),
        page_id=str(answer.get("page_id", "")),
        lines=[line["text"] for line in answer.get("lines", [])],
        seconds=time.perf_counter() - started,
        answer_ms=round(answer_ms, 1),
        stage_seconds=stages,
        speech_wav=str(speech_wav) if spoken is not None else None,
        fovea_event_fraction=fovea_event_fraction(recording),
        answer_lines=list(answer.get("lines", [])),
        spoken=str(answer.get("spoken", "")),
    )
    if recording.text is not None:
        rates = error_rates(recording.text, result.text)
        result.reference, result.cer, result.wer = recording.text, rates.cer, rates.wer
    return result


def _ask_spoken(client: Any, session_id: str) -> bytes:
    """The answer as a WAV; the cloud's one-line reason when it cannot speak."""
    response = client.post(f"/v1/sessions/{session_id}/ask", json={}, headers={"Accept": "audio/wav"})
    if response.status_code != 200:
        raise RuntimeError(f"the cloud could not speak the answer: {response.json().get('detail', response.text)}")
    return bytes(response.content)


# -- command line --------------------------------------------------------------------------------


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "read", help="read a recording end to end (edge -> cloud -> stitch -> OCR) and print the text",
        description=READ_HELP, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("recording", nargs="?",
                        help="recording directory (events.raw, general_eye_gaze.csv, calibration.json), or a bare .raw "
                             "file with --gaze-csv and --calibration")
    parser.add_argument("--gaze-csv", metavar="CSV", help="eye-gaze CSV (for a bare .raw file, or to override the recording's)")
    parser.add_argument("--calibration", metavar="JSON", help="calibration.json (for a bare .raw file, or to override the recording's)")
    parser.add_argument("--demo", action="store_true", help="read the shipped sample recording and compare with its printed text")
    parser.add_argument("--backend", default="local", choices=OCR_BACKENDS,
                        help="OCR backend (default: local, the embedded offline engine); remote ones read DARKREAD_* settings")
    parser.add_argument("--mode", default="frames", choices=["frames", "pages"], help="stream frames (default) or stitch on the glasses")
    parser.add_argument("--infer", default=None, choices=INFER_MODES,
                        help="on-change (default): one fused view per fixation (a tenth of the inferences and bytes); "
                             "every-window: infer every window, send every frame")
    parser.add_argument("--no-lexicon", dest="lexicon", action="store_false",
                        help="report the offline engine's text as read, without the dictionary correction")
    parser.add_argument("--model", metavar="ONNX", help="reconstruction model (default: the shipped one)")
    parser.add_argument("--out", metavar="DIR", help="keep the page image, spool and cloud data here (default: a temp dir)")
    parser.add_argument("--json", action="store_true", help="print one JSON object with the text and per-stage figures")
    parser.add_argument("--say", action="store_true",
                        help="speak the answer (espeak-ng in the cloud; played with paplay/aplay, else the WAV's path is printed)")
    parser.add_argument("--say-out", metavar="FILE.wav", type=Path,
                        help="write the spoken answer to this WAV file (played too with --say)")
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from darkread.core.paths import SAMPLE_RECORDING

    if args.demo:
        path = SAMPLE_RECORDING
    elif args.recording:
        path = Path(args.recording)
    else:
        raise ValueError("give a RECORDING directory, or --demo for the shipped sample")
    if args.say_out is not None and args.say_out.suffix.lower() != ".wav":
        raise ValueError(f"--say-out {args.say_out}: give a .wav file name")
    result = read_recording(path, backend=args.backend, mode=args.mode, model=args.model, out_dir=args.out,
                            lexicon=args.lexicon, infer=args.infer, speech_wav=_speech_wav(args),
                            gaze_csv=args.gaze_csv, calibration=args.calibration)
    if args.json:
        print(json.dumps(result.to_json(), indent=1))
    else:
        print(result.text)
        if args.demo or args.verbose or result.reference is not None:
            _print_summary(result, sys.stderr)
    if result.speech_wav is not None:
        _say(Path(result.speech_wav), play=args.say)
    return 0


def _speech_wav(args: argparse.Namespace) -> Path | None:
    """Where the spoken answer goes: --say-out, else answer.wav in --out, else a file of its own in
    the temp directory (it outlives the read's scratch directory, so it can be played or found)."""
    if args.say_out is not None:
        return Path(args.say_out)
    if not args.say:
        return None
    if args.out is not None:
        return Path(args.out) / "answer.wav"
    with tempfile.NamedTemporaryFile(prefix="darkread-answer-", suffix=".wav", delete=False) as kept:
        return Path(kept.name)


def _say(wav: Path, *, play: bool) -> None:
    """Play the spoken answer, or say where it is."""
    from darkread.say import play_wav

    if not play:
        print(f"spoken answer written to {wav}", file=sys.stderr)
        return
    try:
        player = play_wav(wav)
    except OSError as exc:
        print(f"spoken answer written to {wav} (not played: {exc})", file=sys.stderr)
        return
    print(f"spoke the answer with {player} ({wav})", file=sys.stderr)


def _print_summary(result: ReadResult, stream: Any) -> None:
    kept = result.fovea_event_fraction if result.fovea_event_fraction is not None else 0.0
    print("", file=stream)
    if result.reference is not None:
        print("printed on the page:", file=stream)
        for line in result.reference.splitlines():
            print(f"  {line}", file=stream)
        print(f"CER {result.cer:.1%}  WER {result.wer:.1%}", file=stream)
    print(
        f"{result.events_in:,} events, {kept:.1%} inside the fovea, {result.frames} frames, "
        f"{result.bytes_sent:,} bytes sent ({result.raw_bytes / max(result.bytes_sent, 1):.0f}x less than the raw "
        f"event stream), OCR {result.backend}, {result.seconds:.1f} s (the answer {result.answer_ms:.0f} ms after the "
        "question); " + (f"page: {result.page_png}" if result.page_png else "the page image is kept with --out DIR"),
        file=stream,
    )

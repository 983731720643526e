"""Evaluate recordings: darkread end to end, the RGB baseline, OCR engines on the page, bandwidth.

Each recording's result is a JSON document (``<work_dir>/<name>/result.json``),
so an interrupted evaluation resumes where it stopped and the report can be rebuilt from the
stored results alone.
"""

from __future__ import annotations

import json
import logging
import math
import shutil
import time
import traceback
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import Any

from darkread.cloud.ocr import create_backend
from darkread.cloud.settings import Settings
from darkread.core.image_codec import read_image, write_png
from darkread.core.text_metrics import error_rates
from darkread.edge.reconstruct import default_model_path
from darkread.lab.eval.bandwidth import measure_bandwidth, page_ink_from_png
from darkread.lab.eval.provenance import git_commit, model_digest
from darkread.lab.eval.results import RecordingResult, why_evaluate_again
from darkread.lab.eval.rgb_baseline import baseline_snapshot, read_snapshot
from darkread.lab.eval.selective import match_lines
from darkread.lab.eval.suite import HELD_OUT_FONTS, load_suite, name_matches
from darkread.lab.jobs import run_jobs
from darkread.read import read_recording

logger = logging.getLogger(__name__)

OFFLINE_BACKENDS: tuple[str, ...] = ("rapidocr", "rapidocr-raw", "tesseract", "tesseract-raw")
RAW_SUFFIX = "-raw"  # an offline engine without the dictionary correction
REMOTE_BACKENDS: tuple[str, ...] = ("google", "openai")
RESULT_NAME = "result.json"


def make_ocr_backend(name: str) -> Any:
    """An OCR engine by name, configured from ``DARKREAD_*`` settings like the cloud service;
    ``<engine>-raw``: an offline engine without the dictionary correction."""

    if name.endswith(RAW_SUFFIX):
        return create_backend(Settings(ocr_backend=name.removesuffix(RAW_SUFFIX), ocr_lexicon=False))
    return create_backend(Settings(ocr_backend=name))


def remote_configured(name: str) -> bool:

    settings = Settings()
    if name == "google":
        return settings.google_api_key is not None or settings.google_bearer_token is not None
    if name == "openai":
        return settings.openai_api_key is not None
    return False


def available_backends(names: Sequence[str] | None = None) -> list[str]:
    """Engines to compare: the offline ones that are installed, remote ones only when configured."""
    wanted = list(names) if names is not None else [*OFFLINE_BACKENDS, *REMOTE_BACKENDS]
    ready = []
    for name in wanted:
        if name in REMOTE_BACKENDS and not remote_configured(name):
            continue
        try:
            if make_ocr_backend(name).ready():
                ready.append(name)
            else:
                logger.info("OCR engine %s is not available; left out of the comparison", name)
        except Exception as exc:  # a misconfigured engine must not stop the evaluation
            logger.info("OCR engine %s left out: %s", name, exc)
    return ready


def conditions(recording_dir: Path) -> dict[str, Any]:
    """The recording's conditions from ``meta.json`` (the grouping keys of the report)."""

    meta = json.loads((recording_dir / "meta.json").read_text()) if (recording_dir / "meta.json").is_file() else {}
    font = meta.get("font")
    return {
        "name": recording_dir.name,
        "lux": meta.get("lux"),
        "motion": meta.get("motion"),
        "kind": meta.get("text_kind"),
        "font": font,
        "held_out_font": font in HELD_OUT_FONTS if font else None,
        "xheight_px": meta.get("xheight_px"),
        "duration_s": meta.get("duration_s"),
        "scanpath": (meta.get("scanpath") or {}).get("kind", "model"),
        "reference_chars": len((recording_dir / "text.txt").read_text(encoding="utf-8")),
    }


def _guard(label: str, func: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    try:
        return func()
    except Exception as exc:  # one failing stage is recorded, the others still run
        logger.warning("%s failed: %s", label, exc)
        logger.debug("%s", traceback.format_exc())
        return {"error": f"{type(exc).__name__}: {exc}"}


def evaluate_recording(
    recording_dir: str | Path,
    run_dir: str | Path,
    *,
    backend: str = "local",
    compare: Sequence[str] = (),
    model: str | None = None,
    ocr_cache: dict[str, Any] | None = None,
    infer: str = "every-window",
    rgb: bool = True,
    shed_level: int = 0,
) -> dict[str, Any]:
    """Everything the report needs about one recording (errors are recorded per stage); ``rgb=False``
    leaves out the RGB baseline and the bandwidth figures (which need its snapshot); ``shed_level``
    holds the edge at that shedding level (``edge.load``) for the whole read, as a live edge starved
    of CPU would shed."""

    recording_dir, run_dir = Path(recording_dir), Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    cache = ocr_cache if ocr_cache is not None else {}

    def engine(name: str) -> Any:
        if name not in cache:
            cache[name] = make_ocr_backend(name)
        return cache[name]

    reference = (recording_dir / "text.txt").read_text(encoding="utf-8")

    result: dict[str, Any] = {**conditions(recording_dir), "backend": backend, "commit": git_commit(),
                              "evaluated": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "infer": infer,
                              "model": network_digest(model), **({"edge_shed_level": shed_level} if shed_level else {})}
    read: dict[str, Any] = {}

    def run_darkread() -> dict[str, Any]:
        started = time.perf_counter()
        # a fresh read: an earlier run's cloud data (another session of the same page) would stay
        # beside this one and the attribution could not tell which session the report read
        shutil.rmtree(run_dir / "read", ignore_errors=True)
        r = read_recording(recording_dir, backend=backend, model=model, out_dir=run_dir / "read", infer=infer,
                           prepare_edge=partial(hold_shed_level, level=shed_level) if shed_level else None)
        read["result"] = r
        return {
            "text": r.text, "cer": r.cer, "wer": r.wer, "frames": r.frames, "messages_sent": r.messages_sent,
            "bytes_sent": r.bytes_sent, "events_in": r.events_in, "events_foveated": r.events_foveated,
            "page_png": r.page_png, "seconds": round(time.perf_counter() - started, 2),
            "lines": match_lines(reference, r.answer_lines), "spoken": r.spoken,
        }

    result["darkread"] = _guard(f"{recording_dir.name}: darkread", run_darkread)
    snapshot: dict[str, Any] = {}

    def run_rgb() -> dict[str, Any]:
        snap, source = baseline_snapshot(recording_dir)
        snapshot["snap"] = snap
        crop_png = write_png(run_dir / "rgb_crop.png", snap.crop)
        text = read_snapshot(snap, engine(backend))
        rates = error_rates(reference, text)
        described = {k: v for k, v in snap.describe().items() if not (isinstance(v, float) and math.isnan(v))}
        return {"text": text, "cer": rates.cer, "wer": rates.wer, "source": source, **described, "crop_png": str(crop_png)}

    result["rgb"] = _guard(f"{recording_dir.name}: RGB baseline", run_rgb) if rgb else None

    def run_compare() -> dict[str, Any]:
        page_png = result["darkread"].get("page_png")
        if not page_png:
            raise RuntimeError("no stitched page to read")
        page = read_image(page_png)

        def read_with(name: str) -> dict[str, Any]:
            return {"text": engine(name).read(page).text}

        out = {}
        for name in compare:
            started = time.perf_counter()
            text = _guard(f"{name} on the page", partial(read_with, name))
            if "text" in text:
                rates = error_rates(reference, text["text"])
                text.update(cer=rates.cer, wer=rates.wer, seconds=round(time.perf_counter() - started, 2))
            out[name] = text
        return out

    result["backends"] = _guard(f"{recording_dir.name}: OCR comparison", run_compare) if compare else {}

    def run_bandwidth() -> dict[str, Any]:
        snap = snapshot.get("snap")
        if snap is None or snap.full is None:
            raise RuntimeError("no RGB snapshot to compare with")
        r = read.get("result")
        bw = measure_bandwidth(
            recording_dir, snap.full,
            frames=r.messages_sent if r else None,
            frame_stream_bytes=r.bytes_sent if r else None,
            page_ink=page_ink_from_png(r.page_png) if r else None,
        )
        return bw.to_json()

    result["bandwidth"] = _guard(f"{recording_dir.name}: bandwidth", run_bandwidth) if rgb else None
    (run_dir / RESULT_NAME).write_text(json.dumps(result, indent=1))
    return result


def evaluate_suite(
    suite_dir: str | Path,
    work_dir: str | Path | None = None,
    *,
    backend: str = "local",
    compare: Sequence[str] | None = None,
    model: str | None = None,
    force: bool = False,
    progress: bool = True,
    jobs: int = 1,
    infer: str = "every-window",
    rgb: bool = True,
    shed_level: int = 0,
    match: Sequence[str] = (),
) -> list[RecordingResult]:
    """Evaluate every recording of a suite (those whose names ``match``, when given) with ``jobs``
    worker processes; stored results are reused unless ``force``.

    Per-recording outputs (page image, RGB crop, cloud data, ``result.json``) go to ``work_dir``
    (default: ``SUITE_DIR/eval_runs``), one folder per recording.
    """
    from tqdm import tqdm


    folders = [f for f in load_suite(suite_dir) if not match or name_matches(f.name, match)]
    if not folders:
        raise ValueError(f"--match {' '.join(match)}: no recording of {suite_dir} has such a name")
    runs = Path(work_dir) if work_dir is not None else Path(suite_dir) / "eval_runs"
    engines = available_backends(compare)
    logger.info("%d recordings; OCR comparison on the stitched page with: %s", len(folders), ", ".join(engines) or "none")
    by_name: dict[str, dict[str, Any]] = {}
    todo = []
    network = network_digest(model)
    for folder in folders:
        stored = runs / folder.name / RESULT_NAME
        doc = json.loads(stored.read_text()) if stored.is_file() and not force else None
        reason = None if doc is None else why_evaluate_again(doc, infer, network, shed_level)
        if reason is not None:
            logger.warning("%s %s; evaluating it again in %s mode with network %s", stored.parent, reason, infer, network)
            doc = None
        if doc is not None:
            by_name[folder.name] = doc
        else:
            todo.append(folder)
    bar = tqdm(total=len(folders), initial=len(by_name), desc=f"evaluating ({infer})", unit="rec", disable=not progress)
    # one process reads in turn with one set of OCR engines; each worker process makes its own
    task = partial(_evaluate_in, runs=runs, backend=backend, compare=engines, model=model,
                   ocr_cache={} if jobs <= 1 else None, infer=infer, rgb=rgb, shed_level=shed_level)
    for folder, doc in zip(todo, run_jobs(task, todo, jobs, bar.update), strict=True):
        by_name[folder.name] = doc
    bar.close()
    return [RecordingResult.from_dict(by_name[f.name]) for f in folders]


def hold_shed_level(edge: Any, level: int) -> None:
    """Hold a built edge at shedding ``level`` (``edge.load``): a lossless replay never sheds by
    itself (it waits for inference), so this is how the lab reads a page as a starved edge makes it."""
    edge.pipeline.windows.shed_level = edge.metrics.shed_level = level


def _evaluate_in(folder: Path, runs: Path, **options: Any) -> dict[str, Any]:
    """``evaluate_recording`` of one suite folder into its run folder under ``runs`` (a process task)."""
    return evaluate_recording(folder, runs / folder.name, **options)


def network_digest(model: str | Path | None) -> str:
    """Which weights read a recording (``model``, else the shipped network): its sha256 prefix."""

    path = Path(model) if model is not None else default_model_path()
    return model_digest(path) if path.is_file() else f"{path.name} (missing)"


def load_results(work_dir: str | Path) -> list[RecordingResult]:
    """The results stored under ``work_dir`` (one ``result.json`` per recording folder)."""
    runs = Path(work_dir)
    return [RecordingResult.from_dict(json.loads(p.read_text())) for p in sorted(runs.glob(f"*/{RESULT_NAME}"))]

"""The cloud's side again on frames already made: an evaluated suite's stored frames stitched and
read by the cloud code of now, to measure a change to the stitcher or the reading on the very same
frames, in under a minute for the suite where reading it end to end takes a quarter of an hour.
The stored frames decide the answer: re-read with the code that evaluated them, all 93 recordings
of the suite give the evaluated CER exactly.

Each recording's stored frames (``<work>/<name>/read/cloud``) go through the cloud's paging in seq
order, as a restarted cloud rebuilds its pages from the store; the last page is read line by line
as ``ask`` reads it, each line judged by the shipped line-confidence model (answered or unclear)
and matched to the reference line it reads closest to. Where the simulator's truth is there, the stitcher's placements are checked
against it: each frame's centre on the stitched page against the same pixel's place on the true
page, through the least-squares map between the two (scale and offset per axis); the registration
error is the median distance left, and a frame more than ``MISPLACED_PX`` off is misplaced.
"""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from darkread.cloud.live.paging import Paginator
from darkread.cloud.live.reading import LineReader
from darkread.core.text_metrics import error_rates
from darkread.lab.eval.aggregate import mean
from darkread.lab.eval.attribution import evaluated_runs, stored_frames
from darkread.lab.eval.runner import RESULT_NAME, make_ocr_backend
from darkread.lab.eval.selective import LineOutcome, match_lines, weighted_cer
from darkread.lab.eval.tables import pct
from darkread.lab.truth import PageTruth, load_truth
from darkread.models.train.annotate import page_coordinates, window_rays

MISPLACED_PX = 6.0  # a letter's width at the suite's smallest type: a frame this far off blurs or doubles its words
RESTITCH_NAME = "restitch.json"


@dataclass(frozen=True)
class Restitched:
    name: str
    lux: float
    motion: str
    frames: int
    cer_stored: float  # as the evaluation read it, end to end
    cer: float  # the stored frames stitched and read again
    registration_px: float | None  # median distance of the frames from their true places (None: no truth)
    misplaced: int | None  # frames more than MISPLACED_PX from their true places
    # the answer's lines: [CER of the reference line it matched, that line's characters, answered]
    lines: tuple[tuple[float, int, bool], ...] = ()


def true_centres(truth: PageTruth, frames: Sequence[Any]) -> dict[int, np.ndarray]:
    """Each frame's centre pixel on the true page (texels), by the simulator's pose at its time."""
    out = {}
    for frame in frames:
        h, w = frame.mask.shape
        origin = (int(frame.origin[0]), int(frame.origin[1]))
        rays = window_rays(truth.calibration, origin, (h, w))
        H = truth.pose_at(float(frame.t_us))
        out[int(frame.frame_id)] = page_coordinates(H, rays[[(h // 2) * w + w // 2]])[0] * truth.px_per_mm
    return out


def placement_errors(placed: dict[int, tuple[float, float]], shapes: dict[int, tuple[int, int]],
                     true: dict[int, np.ndarray]) -> np.ndarray:
    """Distance (px) of each placed frame's centre from where the least-squares map (scale and offset
    per axis) between the true page and the stitched one puts its true centre; empty with fewer than 3.
    The map is fitted again without the frames it left more than ``MISPLACED_PX`` (and three times the
    median) off, so that a stretch of misplaced frames does not pull it towards them."""
    ids = [i for i in placed if i in true]
    if len(ids) < 3:
        return np.zeros(0)
    stitched = np.array([[placed[i][0] + shapes[i][1] / 2, placed[i][1] + shapes[i][0] / 2] for i in ids])
    design = np.c_[np.array([true[i] for i in ids]), np.ones(len(ids))]
    errors = np.hypot(*(stitched - design @ np.linalg.lstsq(design, stitched, rcond=None)[0]).T)
    kept = errors <= max(MISPLACED_PX, 3 * float(np.median(errors)))
    if kept.sum() >= 3:
        errors = np.hypot(*(stitched - design @ np.linalg.lstsq(design[kept], stitched[kept], rcond=None)[0]).T)
    return errors


def restitch_recording(recording: Path, run_dir: Path, reader: LineReader) -> Restitched | None:
    """One evaluated recording's stored frames stitched and read again (None: no frames or no result)."""
    result_path = run_dir / RESULT_NAME
    frames = stored_frames(run_dir / "read" / "cloud") if (run_dir / "read" / "cloud").is_dir() else []
    if not frames or not result_path.is_file():
        return None
    result = json.loads(result_path.read_text(encoding="utf-8"))
    paginator = Paginator()
    for frame in frames:
        try:
            paginator.add(frame)
        except ValueError:
            continue  # the cloud refuses such a frame too
    page = paginator.current
    rendered = paginator.render(page) if page is not None else None
    reading = reader.read(rendered) if rendered is not None else None
    text = reading.text if reading is not None else ""
    reference = (recording / "text.txt").read_text(encoding="utf-8")
    answered = [{"text": line.text, "read": bool(line.text.strip()) and line.judgement is not None
                 and line.judgement.status == "read"} for line in (reading.lines if reading is not None else ())]
    lines = tuple((float(m["line_cer"]), int(m["line_ref_chars"]), bool(m["read"])) for m in match_lines(reference, answered))
    errors = np.zeros(0)
    truth = load_truth(recording)
    if truth is not None and page is not None and page.stitcher is not None:
        placed = page.stitcher.snapshot(positions=True).frame_positions
        errors = placement_errors(placed, {int(f.frame_id): f.mask.shape for f in frames}, true_centres(truth, frames))
    stored = result.get("darkread") if isinstance(result.get("darkread"), dict) else {}
    return Restitched(
        name=recording.name, lux=float(result["lux"]), motion=str(result["motion"]), frames=len(frames),
        cer_stored=min(1.0, float(stored.get("cer", 1.0))), cer=min(1.0, error_rates(reference, text).cer),
        registration_px=round(float(np.median(errors)), 2) if errors.size else None,
        misplaced=int((errors > MISPLACED_PX).sum()) if errors.size else None, lines=lines,
    )


def _selective(rows: Sequence[Restitched]) -> tuple[str, str]:
    """Coverage (share of lines answered) and the CER of the answered lines, over ``rows``' lines."""
    lines = [LineOutcome(row.name, row.lux, row.motion, None, cer, chars, {}, read=answered)
             for row in rows for cer, chars, answered in row.lines]
    answered = [line for line in lines if line.read]
    return pct(len(answered) / len(lines) if lines else None), pct(weighted_cer(answered))


def restitch_table(rows: Sequence[Restitched], before: dict[str, dict[str, Any]] | None = None) -> str:
    """Mean CER (stored, and read again) and registration by lux and motion; with ``before`` (an
    earlier run's per-recording figures by name) its CER and misplaced frames beside them."""
    groups: dict[tuple[float, str], list[Restitched]] = defaultdict(list)
    for row in rows:
        groups[(row.lux, row.motion)].append(row)
        groups[(row.lux, "**all**")].append(row)
    head = ["lux", "motion", "n", "CER as evaluated", "CER re-read"]
    if before is not None:
        head += ["CER re-read before"]
    head += ["registration error (median px)", "frames misplaced"]
    if before is not None:
        head += ["frames misplaced before"]
    head += ["lines answered", "CER, answered lines"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---:|" * 2 + "---:|" * (len(head) - 2)]
    for (lux, motion), group in sorted(groups.items(), key=lambda kv: (-kv[0][0], kv[0][1] == "**all**", kv[0][1])):
        checked = [r for r in group if r.registration_px is not None]
        cells = [f"{lux:g}", motion, str(len(group)), pct(mean(r.cer_stored for r in group)), pct(mean(r.cer for r in group))]
        if before is not None:
            cells.append(pct(mean(float(before[r.name]["cer"]) for r in group if r.name in before)))
        cells.append(f"{np.median([r.registration_px for r in checked]):.1f}" if checked else "-")
        cells.append(f"{sum(r.misplaced or 0 for r in checked)} of {sum(r.frames for r in checked)}" if checked else "-")
        if before is not None:
            cells.append(str(sum(int(before[r.name].get("misplaced") or 0) for r in checked if r.name in before)))
        cells.extend(_selective(group))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_restitch(suite: Path, work: Path, out: Path, *, backend: str = "local", before: Path | None = None,
                   progress: bool = True, notes: Sequence[str] = ()) -> Path:
    """Every evaluated recording of ``suite`` (results in ``work``) stitched and read again; a
    Markdown table at ``out`` and the per-recording figures beside it (``.json``, what ``before``
    takes from an earlier run)."""
    from tqdm import tqdm

    evaluated = evaluated_runs(suite, work)
    earlier = None
    if before is not None:
        try:
            earlier = {str(row["name"]): {"cer": float(row["cer"]), "misplaced": row.get("misplaced")}
                       for row in json.loads(before.read_text(encoding="utf-8"))}
        except OSError as exc:
            raise ValueError(f"{before}: cannot be read ({exc.strerror})") from None
        except (ValueError, KeyError, TypeError):
            raise ValueError(f"{before}: not the .json an earlier `darkread eval restitch` wrote beside its report") from None
    reader_backend = make_ocr_backend(backend)
    rows = []
    for run_dir in tqdm(evaluated, desc="re-stitching", unit="rec", disable=not progress):
        recording = suite / run_dir.name
        if (recording / "text.txt").is_file():
            row = restitch_recording(recording, run_dir, LineReader(reader_backend))
            if row is not None:
                rows.append(row)
    if not rows:
        raise FileNotFoundError(f"{work}: no evaluated recording holds stored frames and a result")
    out.parent.mkdir(parents=True, exist_ok=True)
    text = "\n".join([
        "# The stored frames stitched and read again",
        "",
        f"`darkread eval restitch {suite}`: {len(rows)} evaluated recordings (frames in `{work}`), OCR `{backend}`. "
        "Each recording's stored frames go through the cloud's paging as a restarted cloud rebuilds its pages, and the "
        "last page is read as `ask` reads it, its lines judged by the shipped line-confidence model (answered: read, not "
        "unclear; their CER over the characters of the reference lines they matched). Registration error: each frame's "
        "centre on the stitched page against its true place (the simulator's pose), through the least-squares map "
        "between the two pages; misplaced: more than "
        f"{MISPLACED_PX:g} px off."
        + (f" Before: `{before}`." if before is not None else ""),
        *([""] + [f"- {note}" for note in notes] if notes else []),
        "",
        restitch_table(rows, earlier),
        "",
    ])
    out.write_text(text, encoding="utf-8")
    out.with_suffix(".json").write_text(json.dumps([asdict(r) for r in rows], indent=1), encoding="utf-8")
    return out

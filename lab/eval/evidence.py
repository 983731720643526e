"""How much of a page's ink the events themselves show: the bound on what any network can draw.

``eval attribute`` says the dark pages fail on their frames (10 lux: 64 % of the ink found). This
module asks whether the ink is in the events the network is given at all. For windows cut every
``every_ms`` along a synthetic recording's gaze, as the edge cuts them (fovea, the newest N events,
moved back along the head's motion, in dim light without isolated events), it scores the window's
event-count image against the window's true ink (the simulator's page under its true pose at the
window's newest event):

* **separability**: the probability that an ink pixel has more (blurred) events than a paper pixel
  3 px or more from any ink (the area under the ROC curve; 0.5 = the events do not tell ink from
  paper, 1.0 = perfectly);
* **coverage**: the share of true ink with an event within 1 px (``attribution.ink_found``, the
  definition the frames' ink recall uses): a frame can find little more ink than this.

Both for windows of several lengths (the edge's 1600 events, and longer ones: what temporal context
could gather) and with the head's motion as the edge measures it (``edge.deblur``: one steady
displacement per window) or known exactly (``eval.true_motion``: what an inertial sensor would give).
Pure scoring functions at the top; the recording loop and the report below.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path

import cv2
import numpy as np

from darkread.edge.deblur import DeblurConfig
from darkread.edge.denoise import DenoiseConfig
from darkread.edge.events import Events
from darkread.edge.fovea import FoveaConfig, window_events, window_origin
from darkread.edge.frame import clean_window
from darkread.edge.gaze import GazeMapper
from darkread.lab.eval.attribution import ink_found, window_truth
from darkread.lab.eval.suite import load_suite
from darkread.lab.eval.tables import page_as_section
from darkread.lab.eval.true_motion import TrueHeadMotion
from darkread.lab.jobs import run_jobs
from darkread.lab.truth import load_truth_and_pose
from darkread.models.train.annotate import window_rays
from darkread.models.train.windows import read_events

log = logging.getLogger(__name__)

EVIDENCE_NAME = "evidence.md"
LENGTHS = (1600, 3200, 6400)  # events per window: the edge's, and two and four times as many
ESTIMATES = ("measured", "exact")  # the head's motion as the edge measures it, or known exactly
PAPER_MARGIN_PX = 3  # paper: pixels at least this far from any ink
BLUR_SIGMA_PX = 1.0  # the count image is blurred this much before scoring (strokes are ~2 px wide)
FIRST_WINDOW_US = 300_000  # windows start this far into a recording: past the first fixation's landing ...
EVERY_MS = 80.0  # ... one every this often ...
MAX_WINDOWS = 25  # ... at most this many per recording


# -- scores: arrays in, numbers out --------------------------------------------------------------

def count_image(events: Events, origin: tuple[int, int], shape_hw: tuple[int, int]) -> np.ndarray:
    """float32 [h, w]: events per pixel of the window at ``origin`` (events outside it ignored)."""
    h, w = shape_hw
    x = events["x"].astype(np.intp) - origin[0]
    y = events["y"].astype(np.intp) - origin[1]
    inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
    counts = np.bincount(y[inside] * w + x[inside], minlength=h * w)
    return counts.astype(np.float32).reshape(h, w)


def ink_and_paper_scores(counts: np.ndarray, ink: np.ndarray, margin_px: int = PAPER_MARGIN_PX,
                         sigma_px: float = BLUR_SIGMA_PX) -> tuple[np.ndarray, np.ndarray]:
    """The blurred event counts at the true ink pixels and at the paper pixels ``margin_px`` or more
    from any ink."""
    blurred = cv2.GaussianBlur(counts.astype(np.float32), (0, 0), sigma_px)
    ink = ink.astype(bool)
    near = cv2.dilate(ink.astype(np.uint8), np.ones((2 * margin_px + 1, 2 * margin_px + 1), np.uint8)).astype(bool)
    return blurred[ink], blurred[~near]


def separability(positive: np.ndarray, negative: np.ndarray) -> float:
    """P(a positive score > a negative one), ties counting half (the Mann-Whitney AUC); NaN when
    either side is empty."""
    if positive.size == 0 or negative.size == 0:
        return float("nan")
    ordered = np.sort(negative.ravel())
    below = np.searchsorted(ordered, positive.ravel(), side="left")
    not_above = np.searchsorted(ordered, positive.ravel(), side="right")
    return float((below.sum() + 0.5 * (not_above - below).sum()) / (positive.size * ordered.size))


# -- one recording -----------------------------------------------------------------------------

@dataclass(frozen=True)
class Evidence:
    """One recording's windows scored: per "<estimate>/<length>", the pooled separability and coverage."""

    name: str
    lux: float
    motion: str
    windows: int
    separability: dict[str, float]
    coverage: dict[str, float]


def _key(estimate: str, length: int) -> str:
    return f"{estimate}/{length}"


def recording_evidence(recording: str | Path, lengths: Sequence[int] = LENGTHS, every_ms: float = EVERY_MS,
                       max_windows: int = MAX_WINDOWS) -> Evidence | None:
    """Score the recording's windows (None for one without the simulator's truth: a real recording)."""

    path = Path(recording)
    loaded = load_truth_and_pose(path)
    if loaded is None:
        return None
    truth, pose = loaded
    exact = TrueHeadMotion(truth, pose.t_us, pose.H)
    rec, events, sensor_wh = read_events(path)
    meta = json.loads((path / "meta.json").read_text(encoding="utf-8")) if (path / "meta.json").is_file() else {}
    mapper, fovea = GazeMapper(rec.calibration, rec.gaze()), FoveaConfig()
    shape_hw = (fovea.height, fovea.width)
    longest = max(lengths)
    times = np.arange(int(events["t"][0]) + FIRST_WINDOW_US, int(events["t"][-1]), int(every_ms * 1000))[:max_windows]
    pooled: dict[str, tuple[list[np.ndarray], list[np.ndarray]]] = {_key(e, n): ([], []) for e in ESTIMATES for n in lengths}
    found = {_key(e, n): np.zeros(2, np.int64) for e in ESTIMATES for n in lengths}
    scored = 0
    for t in times:
        gaze = mapper.at(int(t))
        if gaze is None:
            continue
        origin = window_origin(gaze.pixel, sensor_wh, fovea)
        end = int(np.searchsorted(events["t"], t, side="right"))
        recent = events[max(0, end - 400 * longest) : end]
        widest = window_events(recent, origin, fovea, longest)
        if widest.shape[0] < longest:
            continue  # every length scored on the same windows
        scored += 1
        for n in lengths:
            sensed = widest[-n:]  # the newest n of the window's events: ``window_events(recent, ..., n)``
            nearby = recent[int(np.searchsorted(recent["t"], sensed["t"][0], side="left")) :]
            H = truth.pose_at(float(sensed["t"][-1]))
            ink = window_truth(truth, window_rays(truth.calibration, origin, shape_hw), shape_hw, H)
            for estimate in ESTIMATES:
                window, _, _ = clean_window(sensed, nearby, origin, shape_hw, sensor_wh, DeblurConfig(), DenoiseConfig(),
                                            exact if estimate == "exact" else None)
                counts = count_image(window, origin, shape_hw)
                on_ink, on_paper = ink_and_paper_scores(counts, ink)
                pooled[_key(estimate, n)][0].append(on_ink)
                pooled[_key(estimate, n)][1].append(on_paper)
                found[_key(estimate, n)] += ink_found((counts > 0).astype(np.uint8), ink)[:2]
    if not scored:
        return Evidence(path.name, float(meta.get("lux", 0.0)), str(meta.get("motion", "")), 0, {}, {})
    return Evidence(
        name=path.name, lux=float(meta.get("lux", 0.0)), motion=str(meta.get("motion", "")), windows=scored,
        separability={k: round(separability(np.concatenate(p), np.concatenate(q)), 4) for k, (p, q) in pooled.items()},
        coverage={k: round(float(c[0] / max(1, c[1])), 4) for k, c in found.items()},
    )


# -- the suite ---------------------------------------------------------------------------------

def evidence_table(rows: Sequence[Evidence], lengths: Sequence[int] = LENGTHS) -> list[str]:
    """Markdown: mean separability per lux and head motion for every estimate and length, and the
    coverage of the edge's own windows (measured motion, the shortest length)."""
    cols = [_key(e, n) for e in ESTIMATES for n in lengths]
    first = _key(ESTIMATES[0], lengths[0])
    head = ["| lux | motion | n |", *[f" {e} motion, {n} ev |" for e in ESTIMATES for n in lengths],
            f" ink with an event within 1 px ({lengths[0]} ev, measured) |"]
    lines = ["".join(head), "|---:|---|---:|" + "---:|" * (len(cols) + 1)]
    rows = [r for r in rows if r.windows]
    for lux in sorted({r.lux for r in rows}, reverse=True):
        at_lux = [r for r in rows if r.lux == lux]
        motions = [m for m in ("still", "normal", "walking") if any(r.motion == m for r in at_lux)]
        for motion in [*motions, "all"]:
            group = at_lux if motion == "all" else [r for r in at_lux if r.motion == motion]
            label = "**all**" if motion == "all" else motion
            cells = "".join(f" {np.nanmean([r.separability[c] for r in group]):.3f} |" for c in cols)
            lines.append(f"| {lux:g} | {label} | {len(group)} |{cells} {100 * np.mean([r.coverage[first] for r in group]):.0f}% |")
    return lines


def write_evidence(suite: str | Path, out: str | Path, *, lengths: Sequence[int] = LENGTHS, jobs: int = 1,
                   progress: bool = True) -> Path:
    """Score every synthetic recording of ``suite``; write the report (``out``: a .md file or a
    folder) and the per-recording figures beside it (.json). Returns the report's path."""

    out = Path(out)
    report = out if out.suffix == ".md" else out / EVIDENCE_NAME
    recordings = load_suite(suite)

    from tqdm import tqdm


    bar = tqdm(total=len(recordings), unit="rec", desc="evidence", disable=not progress)
    rows = run_jobs(partial(recording_evidence, lengths=tuple(lengths)), recordings, jobs, bar.update)
    bar.close()
    kept = [r for r in rows if r is not None]
    if not kept:
        raise ValueError(f"{suite}: no recording carries the simulator's truth (pose_truth.npz, page_ink.npz); "
                         "the evidence needs synthetic recordings (`darkread eval make-suite`)")
    lines = [
        "# How much of the ink the events show",
        "",
        f"`darkread eval evidence {Path(suite).name}`: {len(kept)} synthetic recordings, up to {MAX_WINDOWS} windows each "
        f"(every {EVERY_MS:g} ms from {FIRST_WINDOW_US / 1e6:g} s, where the gaze rests, and only where the fovea holds the "
        "longest window's events). Each window is cut as the edge cuts it: the newest N foveated events, moved back along the "
        "head's motion, in dim light without isolated events. Its event counts per pixel (blurred by 1 px) "
        "are scored against its true ink: the chance that an ink pixel has more events than a paper pixel "
        f"{PAPER_MARGIN_PX} px or more from ink (0.5: the events cannot tell them apart; 1: perfectly). "
        "*measured*: the motion as the edge finds it (one steady displacement per window, `edge.deblur`); "
        "*exact*: the simulator's true head motion (what an inertial sensor would give). The last column is "
        "the share of true ink with any event within 1 px in the edge's own windows: the frames' ink recall "
        "(attribution.md) cannot go much above it.",
        "",
        *evidence_table(kept, lengths),
        "",
    ]
    report.parent.mkdir(parents=True, exist_ok=True)
    report.write_text("\n".join(lines), encoding="utf-8")
    report.with_suffix(".json").write_text(json.dumps([asdict(r) for r in kept], indent=1) + "\n", encoding="utf-8")
    return report


def evidence_section(out_dir: str | Path) -> list[str]:
    """The report's "How much ink the events show" section: ``evidence.md`` beside it (written by
    ``darkread eval evidence``); nothing when there is none."""
    return page_as_section(Path(out_dir) / EVIDENCE_NAME, "How much of the ink the events show")

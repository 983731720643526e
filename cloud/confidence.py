"""How sure the answer is of each line, and what would help when it is not.

Each line's *evidence* is what the pipeline knows about it: the recogniser's per-character
probabilities, how many frames covered its ink and how much they agreed (dark pixels where all
frames saw ink, grey where they disagreed), its height, how often frames came while the page was
read and how fast the head moved, how much the glasses were shedding (a live edge that cannot keep
up makes fewer frames and views: ``edge.load``, said in each view), the light the glasses measured
at the page (``light_lux`` in each frame and view), and whether its words are dictionary words. A
small logistic model (``line_confidence.json``, fitted on the synthetic suite by ``darkread eval
calibrate``) turns the evidence into the probability
that the line was read right. A line below the model's ``answer_threshold`` is ``unclear``: the
answer does not guess at it, and says what would help (``REASONS``) from the same evidence.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from importlib.resources import files
from pathlib import Path
from typing import Literal

import numpy as np

from .errors import ConfidenceModelError

Reason = Literal["glasses_busy", "too_dark", "too_much_motion", "too_small", "look_again"]
# reason code -> what the spoken answer says: plain words that survive the synthetic voice (an
# offline recogniser hears "please stop moving" word for word, "hold still" as "pulled deal")
REASONS: dict[str, str] = {
    "glasses_busy": "The glasses could not keep up. Look at that line again.",
    "too_dark": "Please add more light.",
    "too_much_motion": "Please stop moving.",
    "too_small": "The text is too small: come closer.",
    "look_again": "Look at that line again.",
}
FEATURES: tuple[str, ...] = (
    "ocr_mean", "ocr_min", "ocr_low_share", "log_chars", "height_px", "ink_solid", "log_views",
    "log_frame_rate", "log_head_speed", "known_share", "corrected_share", "edge_shed", "log_lux",
)
SHED_EVIDENCE = "edge_shed"  # the mean shedding level of the line's page (``edge.load``)
LIGHT_EVIDENCE = "log_lux"  # log of the light the glasses measured at the line's page, lux
MODEL_FILE = "line_confidence.json"
_WORD = re.compile(r"[A-Za-z]+")
LOW_CHAR_PROB = 0.6  # a character read with less than this probability counts as doubtful
BUSY_SHED_LEVEL = 1.5  # the page's views made at this mean shedding level or deeper (one frame per view and
# less, ``edge.load``): a line is unclear first because the glasses could not keep up


@dataclass(frozen=True)
class LineJudgement:
    confidence: float  # probability the line reads right (calibrated)
    status: Literal["read", "unclear"]
    reasons: tuple[str, ...]  # what would help, when unclear
    evidence: dict[str, float]


@dataclass(frozen=True)
class ConfidenceModel:
    """Logistic regression on standardised evidence, plus the limits the reasons are judged by."""

    features: tuple[str, ...]
    mean: tuple[float, ...]
    scale: tuple[float, ...]
    weights: tuple[float, ...]
    intercept: float
    answer_threshold: float  # lines less likely right than this are unclear
    dark_ink_solid: float  # with a still head, frames agreeing on less of the ink than this: the light is the likely cause
    fast_head_speed: float  # log(1 + px/s) above which motion is the likely cause
    small_height_px: float  # lines lower than this are too small to read
    # the thresholds of pages the glasses made while shedding, by level (the page's mean shedding level,
    # rounded; ``edge.load``); a level not listed: ``answer_threshold``. One threshold for every page is set
    # by the pages of glasses that kept up, and a starved page's lines fail in ways the rest of its
    # evidence sees less (a skipped fixation leaves a line fewer looks)
    shed_thresholds: tuple[tuple[int, float], ...] = ()
    # pages the glasses measured dimmer than this (lux) were too dark to read well: more light is the
    # advice. Fitted, not the glasses' own dark-profile level: their estimate assumes a typical sensor's
    # background, and a noisier one reads a lit page as dim (docs/eval/measured_light.md). None: the
    # model saw no measured light, and the frames' agreement stands in for it
    dim_lux: float | None = None
    # the answer threshold of pages measured dimmer than ``dim_lux``: in dim light the evidence the
    # model weighs misjudges more lines (frames agree on a wrong letter), so the line one threshold
    # for every page draws is set by lit pages and lets dim ones through at a higher risk. None: one
    # threshold for every light
    dim_threshold: float | None = None

    @classmethod
    def from_json(cls, data: dict) -> ConfidenceModel:
        return cls(
            tuple(data["features"]), tuple(data["mean"]), tuple(data["scale"]), tuple(data["weights"]),
            float(data["intercept"]), float(data["answer_threshold"]), float(data["dark_ink_solid"]),
            float(data["fast_head_speed"]), float(data["small_height_px"]),
            tuple((int(level), float(t)) for level, t in sorted(data.get("shed_thresholds", {}).items())),
            None if data.get("dim_lux") is None else float(data["dim_lux"]),
            None if data.get("dim_threshold") is None else float(data["dim_threshold"]),
        )

    def threshold_for(self, evidence: dict[str, float]) -> float:
        """The answer threshold for a line with this evidence: its shedding level's and, on a page measured
        dim, the dim pages' (never below the model's)."""
        level = shed_level_of(evidence)
        dim_page = [self.dim_threshold] if self.dim_threshold is not None and measured_dim(evidence, self) else []
        return max([self.answer_threshold, *(t for at, t in self.shed_thresholds if at == level), *dim_page])

    def probability(self, evidence: dict[str, float]) -> float:
        x = np.array([evidence.get(name, mean) for name, mean in zip(self.features, self.mean)], dtype=np.float64)
        z = float(np.dot((x - np.array(self.mean)) / np.array(self.scale), self.weights) + self.intercept)
        return 1.0 / (1.0 + math.exp(-max(-50.0, min(50.0, z))))


@lru_cache(maxsize=4)
def load_model(path: str | None = None) -> ConfidenceModel:
    """The shipped model (``darkread/cloud/data/line_confidence.json``), or the one at ``path``;
    ``ConfidenceModelError`` naming the file when it cannot be read or is not a model."""
    where = path or f"the shipped {MODEL_FILE}"
    try:
        text = Path(path).read_text(encoding="utf-8") if path else (files("darkread.cloud") / "data" / MODEL_FILE).read_text(encoding="utf-8")
        model = ConfidenceModel.from_json(json.loads(text))
    except OSError as exc:
        raise ConfidenceModelError(f"{where}: cannot read the line-confidence model ({exc.strerror or exc})") from None
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        detail = f"no {exc}" if isinstance(exc, KeyError) else str(exc)
        raise ConfidenceModelError(f"{where}: not a line-confidence model ({detail}); `darkread eval calibrate` writes one") from None
    if not len(model.features) == len(model.mean) == len(model.scale) == len(model.weights):
        raise ConfidenceModelError(f"{where}: not a line-confidence model (features, mean, scale and weights differ in length)")
    return model


@dataclass(frozen=True)
class PageConditions:
    """What the page's frames say about how it was read (None where unknown, e.g. a glasses page)."""

    frame_rate_hz: float | None = None
    head_speed_px_s: float | None = None
    shed_level: float | None = None  # the mean shedding level of its frames and views (``edge.load``)
    light_lux: float | None = None  # the light the glasses measured at the page (geometric mean over its frames)


def line_evidence(
    grey: np.ndarray, box: tuple[int, int, int, int], text: str, raw_text: str, char_scores: Sequence[float] | None,
    known_share: float, views: np.ndarray | None = None, conditions: PageConditions = PageConditions(),
) -> dict[str, float]:
    """The evidence about one line (see the module docstring); ``raw_text``: before the correction."""
    x0, y0, x1, y1 = box
    darkness = 1.0 - grey[y0:y1, x0:x1].astype(np.float32) / 255.0
    inked = darkness > 0.1
    scores = np.asarray(char_scores if char_scores else [0.0], dtype=np.float64)
    raw_words, words = raw_text.split(), text.split()
    changed = sum(a != b for a, b in zip(raw_words, words)) + abs(len(raw_words) - len(words))
    evidence = {
        "ocr_mean": float(scores.mean()),
        "ocr_min": float(scores.min()),
        "ocr_low_share": float((scores < LOW_CHAR_PROB).mean()),
        "log_chars": math.log1p(len(text)),
        "height_px": float(y1 - y0),
        "ink_solid": float((darkness[inked] > 0.75).mean()) if inked.any() else 0.0,
        "known_share": known_share,
        "corrected_share": changed / max(1, len(words)),
    }
    if views is not None and inked.any():
        evidence["log_views"] = math.log1p(float(np.median(views[y0:y1, x0:x1][inked])))
    if conditions.frame_rate_hz:
        evidence["log_frame_rate"] = math.log(conditions.frame_rate_hz)
    if conditions.head_speed_px_s is not None:
        evidence["log_head_speed"] = math.log1p(conditions.head_speed_px_s)
    if conditions.shed_level is not None:
        evidence[SHED_EVIDENCE] = conditions.shed_level
    if conditions.light_lux is not None and conditions.light_lux > 0:
        evidence[LIGHT_EVIDENCE] = math.log(conditions.light_lux)
    return evidence


def known_word_share(text: str, known: Callable[[str], bool] | None) -> float:
    """Share of a line's words (two letters or more) that ``known`` knows; 1 without words or a dictionary."""
    words = [w for w in _WORD.findall(text) if len(w) > 1]
    return sum(known(w) for w in words) / len(words) if words and known is not None else 1.0


def judge(evidence: dict[str, float], model: ConfidenceModel) -> LineJudgement:
    """The line's calibrated confidence, whether it is answered, and if not what would help."""
    p = model.probability(evidence)
    if p >= model.threshold_for(evidence):
        return LineJudgement(round(p, 4), "read", (), evidence)
    return LineJudgement(round(p, 4), "unclear", reasons_for(evidence, model), evidence)


def busy(evidence: dict[str, float]) -> bool:
    """Whether the line's page was made by glasses shedding at ``BUSY_SHED_LEVEL`` or deeper."""
    return evidence.get(SHED_EVIDENCE, 0.0) >= BUSY_SHED_LEVEL


def moving(evidence: dict[str, float], model: ConfidenceModel) -> bool:
    """Whether the head moved fast enough while the line's page was read to blame the motion."""
    return evidence.get("log_head_speed", -math.inf) > model.fast_head_speed


def dim(evidence: dict[str, float], model: ConfidenceModel) -> bool:
    """Whether the line's page was too dim to read well: by the glasses' light measurement where
    there is one (and the model a limit for it), else by frames that agreed on little of the ink
    while the head was still."""
    if LIGHT_EVIDENCE in evidence and model.dim_lux is not None:
        return measured_dim(evidence, model)
    return evidence.get("ink_solid", math.inf) < model.dark_ink_solid and not moving(evidence, model)


def measured_dim(evidence: dict[str, float], model: ConfidenceModel) -> bool:
    """Whether the glasses measured the line's page dimmer than the model's ``dim_lux`` (False where
    either is missing)."""
    return LIGHT_EVIDENCE in evidence and model.dim_lux is not None and evidence[LIGHT_EVIDENCE] < math.log(model.dim_lux)


def shed_level_of(evidence: dict[str, float]) -> int:
    """The shedding level a line's page is judged at: its mean, rounded (0 for glasses that kept up
    or did not say); the fitter groups the lines it sets ``shed_thresholds`` by the same."""
    return round(evidence.get(SHED_EVIDENCE, 0.0))


def reasons_for(evidence: dict[str, float], model: ConfidenceModel) -> tuple[str, ...]:
    """What would help an unclear line, from its evidence: glasses that keep up, stillness, light,
    size; else a second look.

    Where the glasses measured the light and the model knows what dim measures as, the light
    decides: "more light" for a page dimmer than ``dim_lux``, never for a lit one. Elsewhere the
    frames' agreement stands in:
    frames disagree in dim light and when the head moves fast, so only with a still head is the
    disagreement put down to the light."""
    reasons = ["glasses_busy"] if busy(evidence) else []
    if dim(evidence, model):
        reasons.append("too_dark")
    if moving(evidence, model):
        reasons.append("too_much_motion")
    if evidence.get("height_px", math.inf) < model.small_height_px:
        reasons.append("too_small")
    return tuple(reasons) or ("look_again",)


def page_reasons(judgements: Sequence[LineJudgement]) -> tuple[str, ...]:
    """The reasons the unclear lines share most, most common first (none when no line is unclear)."""
    counts: dict[str, int] = {}
    for j in judgements:
        for reason in j.reasons:
            counts[reason] = counts.get(reason, 0) + 1
    return tuple(sorted(counts, key=lambda r: (-counts[r], list(REASONS).index(r))))


def spoken_answer(lines: Sequence[tuple[str, LineJudgement | None]]) -> str:
    """What is said: the lines read, each run of unclear lines as "one line unclear" / "N lines
    unclear" (a page of several lines none of which was read: "the whole page is unclear", since
    bands of a smeared page are no count worth saying), and when half the page or more is unclear,
    what would help."""
    unclear = [j for _, j in lines if j is not None and j.status == "unclear"]
    if len(lines) > 1 and len(unclear) == len(lines):
        return "\n".join(["The whole page is unclear.", *(REASONS[r] for r in page_reasons(unclear)[:2])])
    parts: list[str] = []
    run = 0
    for k, (text, judgement) in enumerate([*lines, ("", None)]):
        if judgement is not None and judgement.status == "unclear":
            run += 1
            continue
        if run:
            parts.append("One line unclear." if run == 1 else f"{_number(run)} lines unclear.")
            run = 0
        if k < len(lines) and text.strip():
            parts.append(text)
    if unclear and 2 * len(unclear) >= len(lines):
        parts.extend(REASONS[r] for r in page_reasons(unclear)[:2])
    return "\n".join(parts)


def _number(n: int) -> str:
    words = ("zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten")
    return (words[n] if n < len(words) else str(n)).capitalize()


@dataclass(frozen=True)
class LineRead:
    """One line as the engine gave it, what a judgement needs."""

    text: str
    raw_text: str
    box: tuple[int, int, int, int] | None
    char_scores: tuple[float, ...] | None


def judge_lines(
    lines: Sequence[LineRead], grey: np.ndarray, model: ConfidenceModel, *, known: Callable[[str], bool] | None = None,
    views: np.ndarray | None = None, conditions: PageConditions = PageConditions(),
) -> list[LineJudgement | None]:
    """Each line judged; a band of ink with no text read is unclear (confidence 0); None for a line
    the engine gave no character probabilities or box for (a remote engine: its own confidence is
    not calibrated here, its lines are answered)."""
    out: list[LineJudgement | None] = []
    for line in lines:
        if line.box is not None and not line.text.strip():
            evidence = line_evidence(grey, line.box, "", "", None, 0.0, views, conditions)
            out.append(LineJudgement(0.0, "unclear", reasons_for(evidence, model), evidence))
            continue
        if line.char_scores is None or line.box is None:
            out.append(None)
            continue
        evidence = line_evidence(grey, line.box, line.text, line.raw_text, line.char_scores,
                                 known_word_share(line.text, known), views, conditions)
        out.append(judge(evidence, model))
    return out

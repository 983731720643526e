"""``darkread eval calibrate``: fit the line-confidence model the cloud ships, and report its calibration.

The lines of an evaluated suite, each labelled right (CER at most ``selective.RIGHT_MAX_CER``) or
wrong, are split by recording: recordings 0-3, 8-11, 16-19, ... fit the model, 4-7, 12-15, ... are held out
and only measured (the suite's grid cycles the text kinds within each four). The model is a logistic
regression on standardised evidence (Newton's method, numpy only), its ridge the one that predicts
best across the fitting recordings' two halves. The answer threshold is the lowest confidence whose
answered lines on the fitting half read at ``target_risk`` CER or better; the limits the reasons
are judged by come from the fitting half's known conditions: the share of solid ink (all frames
agreed) halfway between the dim pages (10 lux and below) and the rest, both without walking (at
most the greyest tenth of the lit lines), and the head speed halfway between walking
and the other motions. Written: the model (JSON, ``cloud/data/line_confidence.json`` by default),
and beside the report ``calibration.md`` with the reliability diagram and ECE on the held-out half.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from darkread.cloud.confidence import (
    BUSY_SHED_LEVEL,
    FEATURES,
    LIGHT_EVIDENCE,
    SHED_EVIDENCE,
    ConfidenceModel,
    judge,
    measured_dim,
    shed_level_of,
)
from darkread.lab.eval.plots import _pyplot
from darkread.lab.eval.selective import LineOutcome, reliability, weighted_cer

# on standardised evidence; the one with the best Brier score in two-fold cross-validation on the fitting half is used
RIDGES = (0.1, 0.3, 1.0, 3.0, 10.0)
DIM_LUX = 10.0
MIN_GROUP_LINES = 50  # fewer lines of a group with a threshold of its own (a shedding level, dim pages): too few to set it by
SMALL_HEIGHT_PX = 9.0  # a line band lower than this holds glyphs of about 4 px x-height: below what the network resolves
# the shedding level is fitted apart, on the lines of pages made while the glasses shed (see ``fit_model``)
BASE_FEATURES = tuple(name for name in FEATURES if name != SHED_EVIDENCE)


def split(lines: Sequence[LineOutcome]) -> tuple[list[LineOutcome], list[LineOutcome]]:
    """(fitting, held-out): by the recording's number in blocks of four (the suite's grid cycles the
    four text kinds within a block, so each half holds every kind, and motions alternate)."""
    def held_out(line: LineOutcome) -> bool:
        head = line.recording.split("_", 1)[0]
        return head.isdigit() and (int(head) // 4) % 2 == 1

    return [ln for ln in lines if not held_out(ln)], [ln for ln in lines if held_out(ln)]


def _matrix(lines: Sequence[LineOutcome], fill: np.ndarray | None = None) -> np.ndarray:
    x = np.array([[line.evidence.get(name, np.nan) for name in BASE_FEATURES] for line in lines], dtype=np.float64)
    if fill is None:  # a missing piece of evidence counts as its mean (what the cloud assumes too)
        seen = ~np.isnan(x)
        fill = np.where(seen, x, 0.0).sum(axis=0) / np.maximum(seen.sum(axis=0), 1)
    return np.where(np.isnan(x), fill, x)


def fit_logistic(x: np.ndarray, y: np.ndarray, ridge: float = 1.0, steps: int = 50) -> tuple[np.ndarray, float]:
    """Weights and intercept of a ridge logistic regression on standardised ``x`` (Newton's method)."""
    design = np.hstack([x, np.ones((len(x), 1))])
    w = np.zeros(design.shape[1])
    penalty = np.diag([ridge] * x.shape[1] + [0.0])
    for _ in range(steps):
        p = 1.0 / (1.0 + np.exp(-np.clip(design @ w, -50, 50)))
        gradient = design.T @ (y - p) - penalty @ w
        hessian = design.T @ (design * (p * (1 - p))[:, None]) + penalty + 1e-9 * np.eye(len(w))
        step = np.linalg.solve(hessian, gradient)
        w += step
        if np.abs(step).max() < 1e-8:
            break
    return w[:-1], float(w[-1])


def _midpoint(a: list[float], b: list[float], default: float) -> float:
    return (float(np.median(a)) + float(np.median(b))) / 2 if a and b else default


def _below_lit(dim: list[float], lit: list[float]) -> float:
    """Halfway between the dim lines' medians and the lit ones', but no higher than the lowest tenth
    of the lit lines: the two overlap, and "add more light" for a lit page is wrong advice."""
    return min(_midpoint(dim, lit, 0.0), float(np.percentile(lit, 10)))


def _dark_limit(dim: list[float], lit: list[float]) -> float:
    """Solid ink below which a still page is called too dark (``_below_lit``: in good light a line
    read by few frames is grey too)."""
    return _below_lit(dim, lit) if dim and lit else 0.0


def light_limit(lines: Sequence[LineOutcome]) -> float | None:
    """The measured light (lux) below which a page is called too dark: halfway (in log lux) between
    the dim pages' lines (10 lux and below) and the rest, but no higher than what the dimmest tenth
    of the lit lines measured ("add more light" there would be wrong advice); None without lines of
    both that carry the glasses' measurement."""
    dim = [ln.evidence[LIGHT_EVIDENCE] for ln in lines if LIGHT_EVIDENCE in ln.evidence and (ln.lux or 0) <= DIM_LUX]
    lit = [ln.evidence[LIGHT_EVIDENCE] for ln in lines if LIGHT_EVIDENCE in ln.evidence and (ln.lux or 0) > DIM_LUX]
    return round(math.exp(_below_lit(dim, lit)), 2) if dim and lit else None


def _standardised(lines: Sequence[LineOutcome]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    x = _matrix(lines)
    mean, scale = x.mean(axis=0), x.std(axis=0)
    scale = np.where(scale > 1e-9, scale, 1.0)
    return (x - mean) / scale, np.array([line.right for line in lines], dtype=np.float64), mean, scale


def choose_ridge(lines: Sequence[LineOutcome]) -> float:
    """The ridge with the lowest Brier score when one half of the recordings predicts the other, both ways."""
    recordings = sorted({line.recording for line in lines})
    first = set(recordings[::2])
    halves = [[ln for ln in lines if ln.recording in first], [ln for ln in lines if ln.recording not in first]]
    if min(len(h) for h in halves) < 10:
        return 1.0

    def brier(ridge: float) -> float:
        total = 0.0
        for train, test in (halves, halves[::-1]):
            x, y, mean, scale = _standardised(train)
            w, b = fit_logistic(x, y, ridge)
            p = 1.0 / (1.0 + np.exp(-(((_matrix(test, mean) - mean) / scale) @ w + b)))
            total += float(np.mean((p - np.array([ln.right for ln in test], dtype=np.float64)) ** 2))
        return total

    return min(RIDGES, key=brier)


def fit_shed_weight(base_logit: np.ndarray, shed: np.ndarray, y: np.ndarray, ridge: float = 1.0, steps: int = 50) -> float:
    """The one weight of the shedding level added to fixed logits (a ridge logistic regression with an offset)."""
    w = 0.0
    for _ in range(steps):
        p = 1.0 / (1.0 + np.exp(-np.clip(base_logit + w * shed, -50, 50)))
        step = (float(np.dot(y - p, shed)) - ridge * w) / (float(np.dot(p * (1 - p), shed * shed)) + ridge)
        w += step
        if abs(step) < 1e-10:
            break
    return w


def fit_model(lines: Sequence[LineOutcome], target_risk: float) -> ConfidenceModel:
    """The logistic model on the lines of glasses that kept up, then the shedding level's weight on the
    lines of glasses that shed with the rest held: a page made without shedding is judged as if the
    starved pages had never been seen, and a starved one pays for how much was shed."""
    starved = [ln for ln in lines if ln.evidence.get(SHED_EVIDENCE, 0.0) > 0]
    kept_up = [ln for ln in lines if ln.evidence.get(SHED_EVIDENCE, 0.0) <= 0]
    x, y, mean, scale = _standardised(kept_up)
    weights, intercept = fit_logistic(x, y, choose_ridge(kept_up))
    shed_weight = 0.0
    if starved:
        base_logit = ((_matrix(starved, mean) - mean) / scale) @ weights + intercept
        shed_weight = fit_shed_weight(base_logit, np.array([ln.evidence[SHED_EVIDENCE] for ln in starved]),
                                      np.array([ln.right for ln in starved], dtype=np.float64))
    order = [BASE_FEATURES.index(name) if name != SHED_EVIDENCE else -1 for name in FEATURES]

    def full(values: np.ndarray, shed_value: float) -> tuple[float, ...]:  # every feature's, the shedding level's as given
        return tuple(float(values[i]) if i >= 0 else shed_value for i in order)

    still = [ln for ln in kept_up if ln.motion != "walking" and "ink_solid" in ln.evidence]
    solid_dim = [ln.evidence["ink_solid"] for ln in still if (ln.lux or 0) <= DIM_LUX]
    solid_lit = [ln.evidence["ink_solid"] for ln in still if (ln.lux or 0) > DIM_LUX]
    fast = [ln.evidence["log_head_speed"] for ln in kept_up if "log_head_speed" in ln.evidence and ln.motion == "walking"]
    calm = [ln.evidence["log_head_speed"] for ln in kept_up if "log_head_speed" in ln.evidence and ln.motion != "walking"]
    model = ConfidenceModel(FEATURES, full(mean, 0.0), full(scale, 1.0), full(weights, shed_weight), intercept, 0.0,
                            _dark_limit(solid_dim, solid_lit), _midpoint(fast, calm, 100.0), SMALL_HEIGHT_PX)
    model = replace(model, answer_threshold=lowest_threshold(model, kept_up, target_risk),
                    shed_thresholds=shed_thresholds(model, starved, target_risk), dim_lux=light_limit(kept_up))
    return replace(model, dim_threshold=dim_threshold(model, kept_up, target_risk))


def dim_threshold(model: ConfidenceModel, kept_up: Sequence[LineOutcome], target_risk: float) -> float | None:
    """The answer threshold of pages measured dimmer than the model's ``dim_lux``: the lowest at which
    those lines read at ``target_risk``; None with fewer than ``MIN_GROUP_LINES`` of them, or when the
    model's own threshold already holds them there."""
    dim_lines = [ln for ln in kept_up if measured_dim(ln.evidence, model)]
    if len(dim_lines) < MIN_GROUP_LINES:
        return None
    threshold = lowest_threshold(model, dim_lines, target_risk)
    return threshold if threshold > model.answer_threshold else None


def shed_thresholds(model: ConfidenceModel, starved: Sequence[LineOutcome], target_risk: float) -> tuple[tuple[int, float], ...]:
    """The answer threshold of each shedding level (the page's mean, rounded) with ``MIN_GROUP_LINES``
    lines: the lowest at which its lines read at ``target_risk`` (one frame per view costs little, no
    view for a covered fixation much more)."""
    by_level: dict[int, list[LineOutcome]] = {}
    for line in starved:
        by_level.setdefault(shed_level_of(line.evidence), []).append(line)
    return tuple((level, lowest_threshold(model, group, target_risk)) for level, group in sorted(by_level.items())
                 if level > 0 and len(group) >= MIN_GROUP_LINES)


def lowest_threshold(model: ConfidenceModel, lines: Sequence[LineOutcome], target_risk: float) -> float:
    """The lowest threshold whose answered lines read at ``target_risk`` CER or better."""
    p = np.array([model.probability(line.evidence) for line in lines])
    for threshold in np.round(np.arange(0.0, 1.0, 0.01), 2):
        answered = [line for line, q in zip(lines, p) if q >= threshold]
        risk = weighted_cer(answered)
        if risk is not None and risk <= target_risk:
            return float(threshold)
    return 0.99


def model_json(model: ConfidenceModel, meta: dict[str, Any]) -> str:
    doc = {
        "about": "line confidence: logistic regression on standardised evidence (cloud/confidence.py); "
                 "fitted by `darkread eval calibrate`", **meta,
        "features": list(model.features), "mean": [round(v, 6) for v in model.mean], "scale": [round(v, 6) for v in model.scale],
        "weights": [round(v, 6) for v in model.weights], "intercept": round(model.intercept, 6),
        "answer_threshold": model.answer_threshold,
        **({"shed_thresholds": {str(level): t for level, t in model.shed_thresholds}} if model.shed_thresholds else {}),
        "dark_ink_solid": round(model.dark_ink_solid, 4),
        **({"dim_lux": model.dim_lux} if model.dim_lux is not None else {}),
        **({"dim_threshold": model.dim_threshold} if model.dim_threshold is not None else {}),
        "fast_head_speed": round(model.fast_head_speed, 4), "small_height_px": model.small_height_px,
    }
    return json.dumps(doc, indent=1) + "\n"


def bootstrap_ece(p: np.ndarray, right: np.ndarray, draws: int = 1000, seed: int = 0) -> tuple[float, float]:
    """5th and 95th percentile of the ECE over resamplings of the held-out lines."""
    rng = np.random.default_rng(seed)
    values = []
    for _ in range(draws):
        pick = rng.integers(0, len(p), len(p))
        values.append(reliability(p[pick], right[pick])[0])
    return float(np.percentile(values, 5)), float(np.percentile(values, 95))


def plot_reliability(rows: list[tuple[float, float, int]], ece: float, path: Path) -> Path:

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    ax.plot([0, 1], [0, 1], color="grey", lw=1, ls="--", label="perfectly calibrated")
    ax.plot([r[0] for r in rows], [r[1] for r in rows], "o-", label=f"held-out lines (ECE {ece:.3f})")
    for conf, acc, n in rows:
        ax.annotate(str(n), (conf, acc), textcoords="offset points", xytext=(4, -10), fontsize=7)
    ax.set_xlabel("confidence (predicted probability the line is right)")
    ax.set_ylabel(f"share of lines right (CER <= {100 * 0.04:g} %)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _by_suite(held: Sequence[LineOutcome], p: np.ndarray, right: np.ndarray) -> list[str]:
    """The held-out lines of each suite apart: is the model calibrated in each, not only pooled?"""
    suites = sorted({line.suite for line in held})
    if len(suites) < 2:
        return []
    md = ["By suite (held-out lines; an ECE over a few dozen lines is coarse):", "",
          "| suite | lines | mean confidence | share right | ECE |", "|---|---:|---:|---:|---:|"]
    for suite in suites:
        pick = np.array([line.suite == suite for line in held])
        ece, _ = reliability(p[pick], right[pick])
        md.append(f"| {suite} | {int(pick.sum())} | {p[pick].mean():.2f} | {right[pick].mean():.2f} | {ece:.3f} |")
    return [*md, ""]


def _by_shedding(held: Sequence[LineOutcome], model: ConfidenceModel) -> list[str]:
    """Coverage and risk of the held-out lines at each shedding level the glasses reported (none when
    no line's page was made while shedding)."""
    levels = sorted({shed_level_of(line.evidence) for line in held})
    if levels == [0]:
        return []
    md = ["Pages made while the glasses shed work (`edge.load`; the suite read with `darkread eval run --edge-shed-level`), "
          "held-out lines, read or not:", "",
          "| shedding level | lines | CER, all lines | answered | CER of the answered |", "|---:|---:|---:|---:|---:|"]
    for level in levels:
        group = [line for line in held if shed_level_of(line.evidence) == level]
        answered = [line for line in group if line.read and judge(line.evidence, model).status == "read"]
        risk = weighted_cer(answered)
        md.append(f"| {level} | {len(group)} | {100 * (weighted_cer(group) or 0):.1f} % | {100 * len(answered) / len(group):.1f} % | "
                  + (f"{100 * risk:.1f} % |" if risk is not None else "- |"))
    return [*md, ""]


@dataclass(frozen=True)
class CalibrationCheck:
    """A model's calibration on lines it may never have seen (``check``)."""

    lines: int
    recordings: int
    ece: float
    right_share: float
    held_lines: int  # the lines of the held-out recording numbers (``split``): unseen in fitting even by scene
    held_ece: float | None


def check(lines: Sequence[LineOutcome], model: ConfidenceModel) -> CalibrationCheck:
    """ECE of ``model`` on the read lines given, and on their held-out half (bands read as nothing are
    unclear by rule, not by the model, so they are left out as in fitting)."""
    read = [line for line in lines if line.read]
    if not read:
        raise ValueError("no judged lines to check the model on: evaluate the suite first (`darkread eval run`)")
    held = split(read)[1]

    def ece_of(group: Sequence[LineOutcome]) -> float:
        p = np.array([model.probability(line.evidence) for line in group])
        return reliability(p, np.array([line.right for line in group], dtype=np.float64))[0]

    return CalibrationCheck(len(read), _recordings(read), ece_of(read), float(np.mean([line.right for line in read])),
                            len(held), ece_of(held) if held else None)


def _recordings(lines: Sequence[LineOutcome]) -> int:
    """How many recordings the lines come from (a scene in two suites is two recordings)."""
    return len({(line.suite, line.recording) for line in lines})


def calibrate(lines: Sequence[LineOutcome], model_out: Path, report_dir: Path, target_risk: float,
              sources: Sequence[str] = ()) -> tuple[ConfidenceModel, float]:
    """Fit on the fitting half, measure on the held-out half, write the model and calibration.md;
    ``sources``: the suites the lines came from, as the page names them."""
    fitting, held = split([line for line in lines if line.read])  # bands read as nothing: unclear by rule, not by the model
    held_all = split(lines)[1]
    if len(fitting) < 20 or len(held) < 10:
        raise ValueError(f"too few judged lines to calibrate ({len(fitting)} to fit, {len(held)} held out); evaluate more recordings")
    model = fit_model(fitting, target_risk)
    p = np.array([model.probability(line.evidence) for line in held])
    right = np.array([line.right for line in held], dtype=np.float64)
    ece, rows = reliability(p, right)
    low, high = bootstrap_ece(p, right)
    meta = {"fitted_on": f"{len(fitting)} lines of {_recordings(fitting)} recordings (numbered 0-3, 8-11, 16-19, ...)",
            "held_out_ece": round(ece, 4), "held_out_ece_90": [round(low, 4), round(high, 4)], "held_out_lines": len(held),
            "target_risk": target_risk, **({"suites": list(sources)} if sources else {})}
    model_out.parent.mkdir(parents=True, exist_ok=True)
    model_out.write_text(model_json(model, meta))
    report_dir.mkdir(parents=True, exist_ok=True)
    plot_reliability(rows, ece, report_dir / "reliability.png")
    md = [
        "# Line confidence: calibration",
        "",
        (f"Fitted by `darkread eval calibrate` on {meta['fitted_on']}; measured on the {len(held)} lines of the "
         f"{_recordings(held)} recordings it was not fitted on (4-7, 12-15, ...). A line is right when its CER is "
         f"at most 4 % (one character in a suite line). Answer threshold {model.answer_threshold:g} (the lowest whose "
         f"answered lines on the fitting half read at {100 * target_risk:g} % CER or better)."
         + (" On a page the glasses made while shedding work (`edge.load`; the page's mean level rounded), the lowest "
            "whose answered lines on the fitting half's pages of that level read so: "
            + ", ".join(f"level {level} {t:g}" for level, t in model.shed_thresholds) + "." if model.shed_thresholds else "")
         + (f" On a page the glasses measured dimmer than {model.dim_lux:g} lux, the lowest whose answered lines on the "
            f"fitting half's dim pages read so: {model.dim_threshold:g}." if model.dim_threshold is not None else "")),
        "",
        *([f"Lines from: {'; '.join(sources)}.", ""] if len(sources) > 1 else []),
        (f"**Held-out ECE: {ece:.3f}** (10 equal-width bins; {100 * right.mean():.0f} % of the {len(held)} held-out lines right; "
         f"90 % bootstrap interval over the held-out lines {low:.3f}-{high:.3f}: with this few lines the estimate is coarse)."),
        "",
        "![reliability diagram](reliability.png)",
        "",
        *_by_suite(held, p, right),
        *_by_shedding(held_all, model),
        "| confidence bin (mean) | share right | lines |",
        "|---:|---:|---:|",
        *[f"| {conf:.2f} | {acc:.2f} | {n} |" for conf, acc, n in rows],
        "",
        "Weights (standardised evidence; positive: more likely right):",
        "",
        "| evidence | weight |",
        "|---|---:|",
        *[f"| {name} | {w:+.2f} |" for name, w in zip(model.features, model.weights)],
        "",
        (f"Reasons: the glasses could not keep up when the page's frames came at a mean shedding level of "
         f"{BUSY_SHED_LEVEL:g} or more (first); too much motion above"
         f" {math.expm1(model.fast_head_speed):.0f} px/s of head motion; too dark "
         + (f"when the glasses measured less than {model.dim_lux:g} lux at the page, and where they did not, " if model.dim_lux else "")
         + f"when frames agree on less than {100 * model.dark_ink_solid:.0f} % of the ink with a still head (solid ink: all frames "
         f"saw it); too small below {model.small_height_px:g} px line height."),
        "",
    ]
    (report_dir / "calibration.md").write_text("\n".join(md))
    return model, ece

"""Selective reading: which lines the answer gave, which it called unclear, and how right each was.

Each line of an answer is matched to the reference line it reads closest to (``match_lines``, at
evaluation time) and keeps that line's CER. From those the report states, per light level and
motion: CER over all lines, coverage (the share of lines answered) and CER over the answered lines,
and the risk-coverage curve (every confidence threshold: the share answered and their CER).
Answered or not is judged again from each line's stored evidence with the model given (by
default the shipped one), so the figures follow the model a `darkread eval calibrate` just fitted.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from darkread.cloud.confidence import SHED_EVIDENCE, ConfidenceModel, judge, reasons_for
from darkread.core.text_metrics import error_rates, normalize_text
from darkread.lab.eval.aggregate import sort_key
from darkread.lab.eval.plots import _pyplot
from darkread.lab.eval.tables import pct

RIGHT_MAX_CER = 0.04  # a line reads "right" at this CER or less: at most one character wrong in a 28-character line


def match_lines(reference: str, lines: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The answer's lines, each with ``line_cer`` and ``line_ref_chars`` of the reference line it reads closest to."""
    refs = [line for line in reference.split("\n") if line.strip()]
    out = []
    for line in lines:
        text = str(line.get("text", ""))
        best = min((error_rates(ref, text) for ref in refs), key=lambda r: r.cer, default=None)
        cer = min(1.0, best.cer) if best is not None else 1.0
        chars = best.reference_chars if best is not None and text.strip() else (
            int(np.median([len(normalize_text(ref)) for ref in refs])) if refs else 1)  # a band read as nothing: a typical line
        out.append({**line, "line_cer": round(cer, 4), "line_ref_chars": chars})
    return out


@dataclass(frozen=True)
class LineOutcome:
    recording: str
    lux: float | None
    motion: str | None
    kind: str | None
    cer: float
    ref_chars: int
    evidence: dict[str, float]
    read: bool = True  # False: a band of ink the engine read nothing in (unclear whatever the model says)
    suite: str = ""  # the suite the recording belongs to (several suites hold the same scenes under the same names)

    @property
    def right(self) -> bool:
        return self.cer <= RIGHT_MAX_CER


def outcomes(results: Sequence[Any], suite: str = "") -> list[LineOutcome]:
    """Every judged line of the results (``RecordingResult``) with its CER and evidence; ``suite``: where they came from."""
    out = []
    for r in results:
        doc = r.raw.get("darkread") if isinstance(r.raw.get("darkread"), Mapping) else {}
        for line in doc.get("lines") or []:
            if "line_cer" in line and line.get("evidence"):
                out.append(LineOutcome(str(r.name), r.lux, r.motion, r.kind, float(line["line_cer"]),
                                       int(line.get("line_ref_chars") or 1), _with_shedding(line["evidence"]),
                                       read=bool(str(line.get("text", "")).strip()), suite=suite))
    return out


def _with_shedding(evidence: Mapping[str, float]) -> dict[str, float]:
    """A line's evidence as the cloud gives it now: a page streamed by the glasses (it knows how fast
    the frames came) stored before the views said how much the edge shed was read by a lossless
    replay, which never sheds: level 0."""
    out = dict(evidence)
    if "log_frame_rate" in out:
        out.setdefault(SHED_EVIDENCE, 0.0)
    return out


def weighted_cer(lines: Sequence[LineOutcome]) -> float | None:
    chars = sum(line.ref_chars for line in lines)
    return sum(line.cer * line.ref_chars for line in lines) / chars if chars else None


@dataclass(frozen=True)
class Selective:
    lines: int
    coverage: float | None
    cer_all: float | None
    cer_answered: float | None


def selective(lines: Sequence[LineOutcome], model: ConfidenceModel) -> Selective:
    answered = [line for line in lines if line.read and judge(line.evidence, model).status == "read"]
    return Selective(len(lines), len(answered) / len(lines) if lines else None, weighted_cer(lines), weighted_cer(answered))


def risk_coverage(lines: Sequence[LineOutcome], model: ConfidenceModel) -> tuple[np.ndarray, np.ndarray]:
    """Coverage and CER of the answered lines at every confidence threshold (most confident first)."""
    if not lines:
        return np.zeros(0), np.zeros(0)
    p = np.array([model.probability(line.evidence) if line.read else 0.0 for line in lines])
    order = np.argsort(-p, kind="stable")
    edits = np.cumsum([lines[i].cer * lines[i].ref_chars for i in order])
    chars = np.cumsum([lines[i].ref_chars for i in order])
    return np.arange(1, len(lines) + 1) / len(lines), edits / np.maximum(chars, 1)


def reliability(p: np.ndarray, right: np.ndarray, bins: int = 10) -> tuple[float, list[tuple[float, float, int]]]:
    """Expected calibration error over equal-width confidence bins, and each bin's (mean confidence,
    share right, lines)."""
    edges = np.linspace(0.0, 1.0, bins + 1)
    which = np.clip(np.digitize(p, edges[1:-1]), 0, bins - 1)
    rows, ece = [], 0.0
    for b in range(bins):
        members = which == b
        if members.any():
            conf, acc = float(p[members].mean()), float(right[members].mean())
            ece += members.mean() * abs(conf - acc)
            rows.append((conf, acc, int(members.sum())))
    return float(ece), rows


def unclear_reasons(lines: Sequence[LineOutcome], model: ConfidenceModel) -> str:
    """How often each reason was given to the group's unclear lines, e.g. "too_much_motion 5, look_again 1"."""
    counts: dict[str, int] = {}
    for line in lines:
        judgement = judge(line.evidence, model)
        if not line.read or judgement.status == "unclear":
            for reason in reasons_for(line.evidence, model):
                counts[reason] = counts.get(reason, 0) + 1
    return ", ".join(f"{r} {n}" for r, n in sorted(counts.items(), key=lambda kv: -kv[1])) or "-"


def plot_risk_coverage(groups: Mapping[str, Sequence[LineOutcome]], model: ConfidenceModel, path: Path) -> Path:

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, lines in groups.items():
        coverage, risk = risk_coverage(lines, model)
        if len(coverage):
            line, = ax.plot(coverage, 100 * risk, label=label)
            here = selective(lines, model)
            if here.coverage and here.cer_answered is not None:
                ax.plot([here.coverage], [100 * here.cer_answered], "o", color=line.get_color())
    ax.set_xlabel("coverage (share of lines answered, most confident first)")
    ax.set_ylabel("CER of the answered lines (%)")
    ax.set_xlim(0, 1)
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8, title="dots: the shipped threshold", title_fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def selective_section(results: Sequence[Any], out: Path, model: ConfidenceModel) -> list[str]:
    """The report's "Selective reading" section (empty when no result has judged lines)."""
    lines = outcomes(results)
    if not lines:
        return []
    by_lux: dict[float | None, list[LineOutcome]] = {}
    by_cell: dict[tuple[float | None, str | None], list[LineOutcome]] = {}
    for line in lines:
        by_lux.setdefault(line.lux, []).append(line)
        by_cell.setdefault((line.lux, line.motion), []).append(line)
    plot_risk_coverage({f"{lux:g} lux": by_lux[lux] for lux in sorted(by_lux, key=sort_key)}, model, out / "risk_coverage.png")

    def row(label: str, group: Sequence[LineOutcome]) -> str:
        s = selective(group, model)
        return f"| {label} | {s.lines} | {pct(s.cer_all)} | {pct(s.coverage)} | {pct(s.cer_answered)} | {unclear_reasons(group, model)} |"

    head = ["| {} | lines | CER, all lines | coverage | CER, answered lines | what the unclear lines were told |",
            "|---|---:|---:|---:|---:|---|"]
    return [
        "## Selective reading: what the answer says and what it calls unclear",
        "",
        ("Each line of an answer is judged by the calibrated line-confidence model (`cloud/confidence.py`, "
         "fitted by `darkread eval calibrate`, see [calibration.md](calibration.md)); lines below its threshold are "
         "answered as unclear, with what would help. Lines are matched to the reference line they read closest to; "
         "CER is over characters of the matched reference lines. Coverage: the share of lines answered. Judged "
         f"again from each line's stored evidence with the model shipped now (threshold {model.answer_threshold:g})."),
        "",
        head[0].format("lux"), head[1],
        *[row(f"{lux:g}", by_lux[lux]) for lux in sorted(by_lux, key=sort_key)],
        row("**all**", lines),
        "",
        head[0].format("lux, motion"), head[1],
        *[row(f"{lux:g}, {motion}", by_cell[(lux, motion)]) for lux, motion in sorted(by_cell, key=sort_key)],
        "",
        "![risk-coverage by light level](risk_coverage.png)",
        "",
    ]

"""Typed results of one evaluated recording, read from the JSON document the runner stores.

``runner.evaluate_recording`` writes a plain JSON document per recording (``result.json``: the
conditions plus ``darkread``, ``rgb``, ``backends`` and ``bandwidth`` sections, any of which may be
``{"error": ...}``). The report reads them through these types instead of string paths, so a
missing section is ``None`` and a rate is a number or ``None``. The document itself stays in
``raw`` and is what ``results.json`` keeps.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

CONDITIONS = ("lux", "motion", "kind", "font", "xheight_px", "scanpath")  # what the report groups recordings by
LEGACY_MODE = "every-window"  # results stored before they named their mode were all every-window


def stored_mode(doc: Mapping[str, Any]) -> str:
    """The edge mode a stored result was evaluated in."""
    return str(doc.get("infer") or LEGACY_MODE)


def why_evaluate_again(doc: Mapping[str, Any], infer: str, model: str, shed_level: int = 0) -> str | None:
    """Why a stored result cannot stand for this run (None: it can): another edge mode, weights
    other than ``model`` (a sha256 prefix, ``provenance.model_digest``) or not recorded, or the edge
    held at another shedding level."""
    if stored_mode(doc) != infer:
        return f"holds a {stored_mode(doc)} result"
    if doc.get("model") != model:
        return f"was read with network {doc.get('model') or '(not recorded)'}"
    if int(doc.get("edge_shed_level", 0)) != shed_level:
        return f"was read with the edge at shedding level {int(doc.get('edge_shed_level', 0))}"
    return None


def _number(value: Any) -> float | None:
    """A finite number, else None (missing, NaN, or not a number)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
        return None
    return float(value)


@dataclass(frozen=True)
class Read:
    """One system's reading of a recording: its text and error rates, or why it failed."""

    text: str | None = None
    cer: float | None = None
    wer: float | None = None
    error: str | None = None

    @classmethod
    def from_dict(cls, doc: Any) -> Read | None:
        if not isinstance(doc, Mapping):
            return None
        return cls(doc.get("text"), _number(doc.get("cer")), _number(doc.get("wer")), doc.get("error"))

    def rate(self, metric: str = "cer") -> float | None:
        """CER or WER clipped at 1 (insertions can push a rate above 1; one garbage read must not dominate)."""
        value = self.cer if metric == "cer" else self.wer
        return None if value is None else min(value, 1.0)


@dataclass(frozen=True)
class DarkreadRead(Read):
    """darkread's reading: also the stitched page it read."""

    page_png: str | None = None

    @classmethod
    def from_dict(cls, doc: Any) -> DarkreadRead | None:
        base = Read.from_dict(doc)
        return None if base is None else cls(base.text, base.cer, base.wer, base.error, doc.get("page_png"))


@dataclass(frozen=True)
class RgbRead(Read):
    """The RGB baseline's reading: also how the simulated snapshot was exposed."""

    crop_png: str | None = None
    exposure_ms: float | None = None
    gain: float | None = None
    paper_electrons: float | None = None
    blur_px: float | None = None

    @classmethod
    def from_dict(cls, doc: Any) -> RgbRead | None:
        base = Read.from_dict(doc)
        if base is None:
            return None
        camera = (_number(doc.get(k)) for k in ("exposure_ms", "gain", "paper_electrons", "blur_px"))
        return cls(base.text, base.cer, base.wer, base.error, doc.get("crop_png"), *camera)


@dataclass(frozen=True)
class Bandwidth:
    """Bytes of one recording in each form (``darkread.lab.eval.bandwidth.measure_bandwidth``)."""

    duration_s: float
    events: int
    events_foveated: int
    evt3_bytes: int
    foveated_evt3_bytes: int
    frame_stream_bytes: int
    page_bytes: int
    frames_measured: bool
    rgb: dict[str, int]  # one RGB snapshot: "raw", "png", "jpeg<quality>" -> bytes
    rgb_wh: tuple[int, int] | None

    @classmethod
    def from_dict(cls, doc: Any) -> Bandwidth | None:
        if not isinstance(doc, Mapping) or "error" in doc:
            return None
        return cls(
            float(doc["duration_s"]), int(doc["events"]), int(doc["events_foveated"]), int(doc["evt3_bytes"]),
            int(doc["foveated_evt3_bytes"]), int(doc["frame_stream_bytes"]), int(doc["page_bytes"]),
            bool(doc.get("frames_measured")), {k: int(v) for k, v in doc["rgb"].items()},
            tuple(doc["rgb_wh"]) if doc.get("rgb_wh") else None,
        )


@dataclass(frozen=True)
class RecordingResult:
    """Everything the report knows about one recording."""

    name: str | None
    lux: float | None
    motion: str | None
    kind: str | None
    font: str | None
    held_out_font: bool
    xheight_px: float | None
    duration_s: float | None
    commit: str | None
    evaluated: str | None
    darkread: DarkreadRead | None
    rgb: RgbRead | None
    backends: dict[str, Read]
    bandwidth: Bandwidth | None
    failures: tuple[str, ...]  # "section: error" of every stage that failed
    raw: dict[str, Any] = field(repr=False, compare=False)
    scanpath: str = "model"  # "human": a real reader's fixations replayed (the reading model otherwise)
    infer: str = LEGACY_MODE  # the edge mode it was evaluated in (every-window, on-change)

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> RecordingResult:
        backends_doc = doc.get("backends")
        if not isinstance(backends_doc, Mapping):
            backends_doc = {}
        backends = {name: read for name, value in backends_doc.items() if name != "error"
                    if (read := Read.from_dict(value)) is not None}
        return cls(
            name=doc.get("name"), lux=_number(doc.get("lux")), motion=doc.get("motion"), kind=doc.get("kind"),
            font=doc.get("font"), held_out_font=bool(doc.get("held_out_font")), xheight_px=_number(doc.get("xheight_px")),
            duration_s=_number(doc.get("duration_s")), commit=doc.get("commit"), evaluated=doc.get("evaluated"),
            darkread=DarkreadRead.from_dict(doc.get("darkread")), rgb=RgbRead.from_dict(doc.get("rgb")),
            backends=backends, bandwidth=Bandwidth.from_dict(doc.get("bandwidth")),
            failures=_failures(doc), raw=dict(doc), scanpath=str(doc.get("scanpath") or "model"),
            infer=stored_mode(doc),
        )

    def condition(self, key: str) -> Any:
        """The value of one grouping condition (``CONDITIONS``)."""
        if key not in CONDITIONS:
            raise KeyError(f"{key!r} is not a condition the report groups by ({', '.join(CONDITIONS)})")
        return getattr(self, key)

    def rate(self, system: str, metric: str = "cer") -> float | None:
        """The clipped CER/WER of ``darkread`` or ``rgb``; None when that stage failed or is missing."""
        read = {"darkread": self.darkread, "rgb": self.rgb}[system]
        return None if read is None else read.rate(metric)

    def backend_rate(self, name: str, metric: str = "cer") -> float | None:
        """The clipped CER/WER of one OCR engine on darkread's page; None when it failed or did not run."""
        read = self.backends.get(name)
        return None if read is None else read.rate(metric)


def _failures(doc: Mapping[str, Any]) -> tuple[str, ...]:
    out = []
    for section in ("darkread", "rgb", "backends", "bandwidth"):
        value = doc.get(section)
        if isinstance(value, Mapping) and "error" in value:
            out.append(f"{section}: {value['error']}")
        elif section == "backends" and isinstance(value, Mapping):
            out += [f"OCR engine {name}: {v['error']}" for name, v in value.items() if isinstance(v, Mapping) and "error" in v]
    return tuple(out)


def typed(results: list[Mapping[str, Any]] | list[RecordingResult]) -> list[RecordingResult]:
    """Result documents as ``RecordingResult`` (already typed ones pass through)."""
    return [r if isinstance(r, RecordingResult) else RecordingResult.from_dict(r) for r in results]

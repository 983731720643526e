"""The report's Markdown tables, from typed recording results (one list of lines per table)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from darkread.lab.eval.aggregate import backend_names, bandwidth_rows, group_by, mean, median
from darkread.lab.eval.bandwidth import (
    JPEG_QUALITIES,
    PAPER_FOVEATION_REMOVED,
    PAPER_FRAMES_VS_RGB,
    PAPER_PAGE_VS_RGB,
)
from darkread.lab.eval.results import Bandwidth, RecordingResult

PAPER_CER_30LUX, PAPER_WER_30LUX = 0.025, 0.083  # GPT-4o on real 30-lux recordings (the paper's headline)


def page_as_section(path: str | Path, title: str) -> list[str]:
    """A Markdown page written beside the report (``attribution.md``, ``simulators.md``, ...) as one
    of its sections: under ``title``, without its own title; nothing when there is no such page."""
    path = Path(path)
    if not path.is_file():
        return []
    body = path.read_text(encoding="utf-8").splitlines()
    body = body[1:] if body and body[0].startswith("# ") else body
    return [f"## {title}", *body, ""]


def pct(value: float | None) -> str:
    return "–" if value is None else f"{value:.1%}"


def _bytes(n: float | None) -> str:
    if n is None or (isinstance(n, float) and math.isnan(n)):
        return "–"
    for unit, scale in (("MB", 1e6), ("kB", 1e3), ("B", 1.0)):
        if n >= scale or unit == "B":
            v = n / scale
            return f"{v:.2f} {unit}" if v < 10 and unit != "B" else (f"{v:.1f} {unit}" if v < 100 and unit != "B" else f"{v:.0f} {unit}")
    return f"{n:.0f} B"


def _ratio(x: float | None) -> str:
    if x is None or math.isnan(x):
        return "–"
    return f"{x:,.0f}x" if x >= 10 else f"{x:.1f}x"


def grouped_table(results: Sequence[RecordingResult], key: str | tuple[str, ...], label: str, fmt: Callable[[Any], str] = str) -> list[str]:
    """Markdown rows: per value of ``key``, count and mean CER/WER of darkread and the RGB baseline."""
    lines = [
        f"| {label} | n | darkread CER | darkread WER | RGB CER | RGB WER |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for value, group in group_by(results, key).items():
        cells = [pct(mean(r.rate(s, m) for r in group)) for s in ("darkread", "rgb") for m in ("cer", "wer")]
        lines.append(f"| {fmt(value)} | {len(group)} | " + " | ".join(cells) + " |")
    return lines


def backend_table(results: Sequence[RecordingResult]) -> list[str]:
    names = backend_names(results)
    if not names:
        return ["No OCR engine comparison in these results."]
    lines = ["| text kind | n | " + " | ".join(f"{n} CER" for n in names) + " |", "|---|---:|" + "---:|" * len(names)]
    for kind, group in group_by(results, "kind").items():
        cells = [pct(mean(r.backend_rate(n) for r in group)) for n in names]
        lines.append(f"| {kind} | {len(group)} | " + " | ".join(cells) + " |")
    cells = [pct(mean(r.backend_rate(n) for r in results)) for n in names]
    lines.append(f"| **all** | {len(results)} | " + " | ".join(cells) + " |")
    return lines


def headline_table(results: Sequence[RecordingResult], *, lux: float = 30.0, kind: str = "paragraph") -> list[str]:
    """The paper's headline condition (paragraphs at 30 lux), by motion, against its figures."""
    group = [r for r in results if r.lux == lux and r.kind == kind]
    if not group:
        return [f"No {lux:g}-lux {kind} recordings in these results."]
    lines = [
        "| motion | n | darkread CER (mean) | median | worst | darkread WER | RGB CER | RGB WER |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    seated = [r for r in group if r.motion in ("still", "normal")]
    rows = list(group_by(group, "motion").items()) + [("still + normal", seated), ("**all**", group)]
    for motion, members in rows:
        if not members:
            continue
        cers = [r.rate("darkread") for r in members]
        worst = max((c for c in cers if c is not None), default=None)
        lines.append(
            f"| {motion} | {len(members)} | {pct(mean(cers))} | {pct(median(cers))} | {pct(worst)} | "
            f"{pct(mean(r.rate('darkread', 'wer') for r in members))} | {pct(mean(r.rate('rgb') for r in members))} | "
            f"{pct(mean(r.rate('rgb', 'wer') for r in members))} |"
        )

    def verdict(members: list[RecordingResult]) -> str:
        cer = mean(r.rate("darkread") for r in members)
        side = "at or below" if cer is not None and cer <= PAPER_CER_30LUX else "above"
        return f"{pct(cer)} over {len(members)} recordings, {side} the paper's {PAPER_CER_30LUX:.1%}"

    lines += ["", f"darkread's mean CER on {lux:g}-lux {kind}s: {verdict(group)} (WER {PAPER_WER_30LUX:.1%}; "
                  "GPT-4o on real recordings)."]
    if seated and len(seated) < len(group):
        lines[-1] += f" Reading still or with normal head motion: {verdict(seated)}; while walking it is harder."
    return lines


def scanpath_table(model: Sequence[RecordingResult], human: Sequence[RecordingResult], kind: str = "paragraph") -> list[str]:
    """CER of the recordings replaying a real reader's fixations next to the reading model's, per
    light level and motion (the report's other tables hold the reading model's recordings only)."""
    if not human:
        return ["No recordings with a real reader's scanpath in these results (`darkread eval make-suite` adds six)."]
    lines = [
        "The same kind of pages read along a real reader's fixations (one reader of the oz data, EyeLink, replayed "
        "line by line onto the page with its durations, regressions, skips, sweep undershoot and vertical drift; "
        "`darkread synth recording --scanpath human`) and along the reading model's.",
        "",
        "| lux | motion | real scanpath: n | CER (mean) | worst | reading model: n | CER (mean) |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    for (lux, motion), members in group_by(human, ("lux", "motion")).items():
        same = [r for r in model if r.lux == lux and r.motion == motion and r.kind == kind]
        cers = [r.rate("darkread") for r in members]
        worst = max((c for c in cers if c is not None), default=None)
        lines.append(f"| {lux:g} | {motion} | {len(members)} | {pct(mean(cers))} | {pct(worst)} | {len(same)} | "
                     f"{pct(mean(r.rate('darkread') for r in same))} |")
    return lines


def _sizes(rows: Sequence[Bandwidth]) -> str:
    sizes = sorted({tuple(b.rgb_wh) for b in rows if b.rgb_wh})
    return " or ".join(f"{w} x {h}" for w, h in sizes) if sizes else "unknown size"


STREAMS = {  # what each edge mode sends in mode `frames`: (the stream, its messages)
    "every-window": ("binary frames", "Frame messages"),
    "on-change": ("the view stream", "View messages: one fused view per fixation"),
}


def bandwidth_table(results: Sequence[RecordingResult], beside: Sequence[RecordingResult] = ()) -> list[str]:
    """Medians over recordings, per page (one recording) and per second, next to the paper's ratios;
    ``beside``: another edge mode's run, whose stream and page get their own rows and figures."""
    rows = bandwidth_rows(results)
    if not rows:
        return ["No bandwidth figures in these results."]
    by_mode = [(r[0].infer, bw) for r in (results, beside) if r and (bw := bandwidth_rows(r))]

    def med(get: Callable[[Bandwidth], float | None], among: Sequence[Bandwidth] = rows) -> float | None:
        return median(get(b) for b in among)

    png = med(lambda b: b.rgb["png"])
    counts = ", ".join(f"{len(bw)} in `{mode}`" for mode, bw in by_mode)
    lines = [
        (f"Medians over the recordings of each run ({counts}). A recording is one page; streams are also given per "
         f"second. The RGB snapshot is one full image of {_sizes(rows)} pixels."),
        "",
        "| what is sent | per page | per second | RGB PNG / this |",
        "|---|---:|---:|---:|",
    ]
    rgb_formats = [("raw", "RGB snapshot, uncompressed (8-bit x 3)"), ("png", "RGB snapshot, PNG")]
    rgb_formats += [(f"jpeg{q}", f"RGB snapshot, JPEG q{q}") for q in JPEG_QUALITIES]
    for key, label in rgb_formats:
        size = median(b.rgb.get(key) for b in rows)
        lines.append(f"| {label} | {_bytes(size)} | – | {_ratio(png / size) if png and size else '–'} |")
    streams: list[tuple[Callable[[Bandwidth], int], str, bool, Sequence[Bandwidth]]] = [
        (lambda b: b.evt3_bytes, "all events, EVT3", True, rows),
        (lambda b: b.foveated_evt3_bytes, "foveated events (100 x 200 window at the gaze), EVT3", True, rows),
    ]
    for mode, bw in by_mode:
        stream, messages = STREAMS.get(mode, ("the stream", "messages"))
        streams += [(lambda b: b.frame_stream_bytes, f"`{mode}`: {stream} as sent ({messages}, mode `frames`)", True, bw),
                    (lambda b: b.page_bytes, f"`{mode}`: stitched page as sent (one Page message, mode `pages`)", False, bw)]
    for get, label, is_stream, among in streams:
        page = med(get, among)
        second = median(get(b) / b.duration_s for b in among if b.duration_s) if is_stream else None
        ref = second if is_stream else page
        lines.append(f"| {label} | {_bytes(page)} | {_bytes(second) if second is not None else '–'} | "
                     f"{_ratio(png / ref) if png and ref else '–'} |")
    removed = med(lambda b: 1 - b.events_foveated / b.events if b.events else None)
    lines += [
        "",
        "| figure | measured here (median) | paper |",
        "|---|---:|---:|",
        f"| events removed by foveation | {pct(removed)} | ~{PAPER_FOVEATION_REMOVED:.0%} (real scenes) |",
    ]
    for mode, bw in by_mode:
        stream = STREAMS.get(mode, ("the stream",))[0]
        for fmt, name, paper in (("png", "PNG", f"~{PAPER_FRAMES_VS_RGB:.0f}x"), ("jpeg80", "JPEG q80", "")):
            ratio = median(b.rgb[fmt] / (b.frame_stream_bytes / b.duration_s) if b.frame_stream_bytes else None for b in bw)
            lines.append(f"| one RGB image ({name}) / one second of {stream} (`{mode}`) | {_ratio(ratio)} | {paper} |")
        for fmt, name, paper in (("png", "PNG", f"~{PAPER_PAGE_VS_RGB:.0f}x"), ("jpeg80", "JPEG q80", "")):
            ratio = median(b.rgb[fmt] / b.page_bytes if b.page_bytes else None for b in bw)
            lines.append(f"| one RGB image ({name}) / stitched page (`{mode}`) | {_ratio(ratio)} | {paper} |")
    measured = sum(1 for _, bw in by_mode for b in bw if b.frames_measured)
    lines += [
        "",
        (f"Stream figures measured on a real edge run for {measured} of {sum(len(bw) for _, bw in by_mode)} recordings "
         "(the rest: one frame per 1600 foveated events). Page bytes: the cloud-stitched page of the run, encoded as "
         "the `Page` message the glasses send in mode `pages`."),
    ]
    return lines


def _difference(a: float | None, b: float | None) -> str:
    return "–" if a is None or b is None else f"{(a - b) * 100:+.1f} pp"


def _mode_cells(pairs: Sequence[tuple[RecordingResult, RecordingResult]]) -> str:
    """n, both modes' mean CER and their difference (primary minus beside, percentage points)."""
    a, b = mean(p.rate("darkread") for p, _ in pairs), mean(q.rate("darkread") for _, q in pairs)
    return f"{len(pairs)} | {pct(a)} | {pct(b)} | {_difference(a, b)} |"


def mode_table(pairs: Sequence[tuple[RecordingResult, RecordingResult]], key: str | tuple[str, ...], label: str,
               fmt: Callable[[Any], str] = str) -> list[str]:
    """Mean darkread CER of two edge modes on the same recordings, per value of ``key``, and the difference."""
    if not pairs:
        return ["No recording was evaluated in both modes."]
    first, second = pairs[0][0].infer, pairs[0][1].infer
    lines = [f"| {label} | n | `{first}` CER | `{second}` CER | `{first}` − `{second}` |", "|---|---:|---:|---:|---:|"]
    beside = {p.name: q for p, q in pairs}
    for value, group in group_by([p for p, _ in pairs], key).items():
        lines.append(f"| {fmt(value)} | " + _mode_cells([(p, beside[p.name]) for p in group]))
    lines.append("| **all** | " + _mode_cells(pairs))
    return lines


def mode_headline(pairs: Sequence[tuple[RecordingResult, RecordingResult]], *, lux: float = 30.0,
                  kind: str = "paragraph") -> list[str]:
    """The paper's headline condition in both modes: reading still or with normal head motion, and walking."""
    group = [(p, q) for p, q in pairs if p.lux == lux and p.kind == kind]
    if not group:
        return [f"No {lux:g}-lux {kind} recordings evaluated in both modes."]
    first, second = group[0][0].infer, group[0][1].infer
    lines = [f"| {lux:g}-lux {kind}s | n | `{first}` CER | `{second}` CER | `{first}` − `{second}` |",
             "|---|---:|---:|---:|---:|"]
    rows = [("still + normal", [(p, q) for p, q in group if p.motion in ("still", "normal")]),
            ("walking", [(p, q) for p, q in group if p.motion == "walking"]), ("**all**", group)]
    for label, members in rows:
        if members:
            lines.append(f"| {label} | " + _mode_cells(members))
    return lines


def camera_table(results: Sequence[RecordingResult]) -> list[str]:
    """How the simulated RGB snapshots were exposed, per light level."""
    lines = ["| lux | n | exposure | gain | paper signal | blur (median) |", "|---:|---:|---:|---:|---:|---:|"]
    for lux, group in group_by(results, "lux").items():
        snaps = [r.rgb for r in group if r.rgb is not None and r.rgb.blur_px is not None]
        if not snaps:
            continue
        lines.append(
            f"| {lux:g} | {len(snaps)} | {median(s.exposure_ms for s in snaps):.1f} ms | {median(s.gain for s in snaps):.1f} | "
            f"{median(s.paper_electrons for s in snaps):.0f} e- | {median(s.blur_px for s in snaps):.1f} px |"
        )
    return lines


def per_recording_table(results: Sequence[RecordingResult]) -> list[str]:
    lines = [
        "| recording | lux | motion | kind | font | x-h | darkread CER | RGB CER | darkread text |",
        "|---|---:|---|---|---|---:|---:|---:|---|",
    ]
    for r in results:
        d = r.darkread
        text = d.text if d is not None and d.text is not None else f"error: {(d and d.error) or '?'}"
        text = (text or "").replace("\n", " / ").replace("|", "\\|")
        text = text if len(text) <= 60 else text[:57] + "..."
        font = f"{r.font}{' (held out)' if r.held_out_font else ''}"
        lines.append(
            f"| {r.name} | {r.lux or 0:g} | {r.motion} | {r.kind} | {font} | "
            f"{r.xheight_px or 0:g} | {pct(r.rate('darkread'))} | {pct(r.rate('rgb'))} | {text} |"
        )
    return lines


def failure_lines(results: Sequence[RecordingResult]) -> list[str]:
    return [f"- {r.name}: {failure}" for r in results for failure in r.failures]

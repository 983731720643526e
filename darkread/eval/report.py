"""The evaluation report: Markdown tables and matplotlib plots from per-recording results.

Input is the list of result documents ``runner.evaluate_recording`` writes (conditions plus
``darkread``, ``rgb``, ``backends`` and ``bandwidth`` sections); nothing here runs a model, so a
report can be rebuilt, or tested, from stored results alone. Means of CER/WER clip each recording's
rate at 1.0 (insertions can push a rate above 1, which would let one garbage read dominate).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import math
import subprocess
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from darkread.eval.bandwidth import (
    JPEG_QUALITIES,
    PAPER_FOVEATION_REMOVED,
    PAPER_FRAMES_VS_RGB,
    PAPER_PAGE_VS_RGB,
)

SYSTEMS: tuple[tuple[str, str], ...] = (("darkread", "darkread (event camera)"), ("rgb", "RGB snapshot baseline"))
REPORT_NAME = "README.md"
RESULTS_NAME = "results.json"


@dataclass
class ReportInfo:
    """What the report states about how it was made."""

    date: str = field(default_factory=lambda: dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"))
    commit: str = "unknown"
    backend: str = "local"
    model: str = ""
    suite: str = ""
    notes: list[str] = field(default_factory=list)


def git_commit(repo: str | Path | None = None) -> str:
    """Short hash of HEAD, ``unknown`` outside a git checkout."""
    cwd = Path(repo) if repo else Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], check=False, cwd=cwd, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() if out.returncode == 0 and out.stdout.strip() else "unknown"


def describe_model(path: str | Path) -> str:
    path = Path(path)
    if not path.is_file():
        return f"{path.name} (missing)"
    digest = hashlib.sha256(path.read_bytes()).hexdigest()[:12]
    stamp = dt.datetime.fromtimestamp(path.stat().st_mtime, dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    return f"{path.name} (sha256 {digest}, {path.stat().st_size:,} bytes, {stamp})"


# -- aggregation -----------------------------------------------------------------------------------


def rate(result: dict[str, Any], system: str, metric: str = "cer") -> float | None:
    """A recording's error rate for a system (``darkread``, ``rgb``, or ``backends.<name>``), clipped at 1."""
    section: Any = result
    for part in system.split("."):
        section = section.get(part, {}) if isinstance(section, dict) else {}
    value = section.get(metric) if isinstance(section, dict) else None
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None
    return min(float(value), 1.0)


def mean(values: Iterable[float | None]) -> float | None:
    kept = [v for v in values if v is not None]
    return sum(kept) / len(kept) if kept else None


def group_by(results: Sequence[dict[str, Any]], key: str | tuple[str, ...]) -> dict[Any, list[dict[str, Any]]]:
    """Results grouped by one condition, or by a tuple of conditions (keys are then tuples)."""
    groups: dict[Any, list[dict[str, Any]]] = {}
    for r in results:
        value = tuple(r.get(k) for k in key) if isinstance(key, tuple) else r.get(key)
        groups.setdefault(value, []).append(r)
    return dict(sorted(groups.items(), key=lambda kv: _sort_key(kv[0])))


_ORDER = {"still": 0, "normal": 1, "walking": 2, "letters": 0, "words": 1, "pangram": 2, "paragraph": 3}


def _sort_key(value: Any) -> Any:
    """Numbers ascending, then known categories in their natural order, then the rest by name."""
    if isinstance(value, tuple):
        return tuple(_sort_key(v) for v in value)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return (0, float(value), "")
    return (1, float(_ORDER.get(value, 99)), str(value))


def _pct(value: float | None) -> str:
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


def median(values: Iterable[float | None]) -> float | None:
    kept = sorted(v for v in values if v is not None and not math.isnan(v))
    if not kept:
        return None
    mid = len(kept) // 2
    return kept[mid] if len(kept) % 2 else (kept[mid - 1] + kept[mid]) / 2


def grouped_table(results: Sequence[dict[str, Any]], key: str | tuple[str, ...], label: str, fmt: Any = str) -> list[str]:
    """Markdown rows: per value of ``key``, count and mean CER/WER of darkread and the RGB baseline."""
    lines = [
        f"| {label} | n | darkread CER | darkread WER | RGB CER | RGB WER |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for value, group in group_by(results, key).items():
        cells = [_pct(mean(rate(r, s, m) for r in group)) for s in ("darkread", "rgb") for m in ("cer", "wer")]
        lines.append(f"| {fmt(value)} | {len(group)} | " + " | ".join(cells) + " |")
    return lines


def backend_names(results: Sequence[dict[str, Any]]) -> list[str]:
    names: list[str] = []
    for r in results:
        for name in (r.get("backends") or {}):
            if name != "error" and name not in names:
                names.append(name)
    return names


def backend_table(results: Sequence[dict[str, Any]]) -> list[str]:
    names = backend_names(results)
    if not names:
        return ["No OCR engine comparison in these results."]
    lines = ["| text kind | n | " + " | ".join(f"{n} CER" for n in names) + " |", "|---|---:|" + "---:|" * len(names)]
    for kind, group in group_by(results, "kind").items():
        cells = [_pct(mean(rate(r, f"backends.{n}") for r in group)) for n in names]
        lines.append(f"| {kind} | {len(group)} | " + " | ".join(cells) + " |")
    cells = [_pct(mean(rate(r, f"backends.{n}") for r in results)) for n in names]
    lines.append(f"| **all** | {len(results)} | " + " | ".join(cells) + " |")
    return lines


def sweep_subset(results: Sequence[dict[str, Any]], key: str, *, min_values: int = 3) -> tuple[list[dict[str, Any]], str]:
    """The recordings of one (lux, motion, text kind) condition that vary ``key`` the most, so a sweep
    is not confounded by the other axes; all recordings when no condition has ``min_values`` values."""
    best: tuple[Any, list[dict[str, Any]]] | None = None
    for condition, group in group_by(results, ("lux", "motion", "kind")).items():
        if len({r.get(key) for r in group}) >= min_values and (best is None or len(group) > len(best[1])):
            best = (condition, group)
    if best is None:
        return list(results), f"all {len(results)} recordings"
    (lux, motion, kind), group = best
    return group, f"{lux:g} lux, {motion} motion, {kind}: {len(group)} recordings"


PAPER_CER_30LUX, PAPER_WER_30LUX = 0.025, 0.083  # GPT-4o on real 30-lux recordings (the paper's headline)


def headline_table(results: Sequence[dict[str, Any]], *, lux: float = 30.0, kind: str = "paragraph") -> list[str]:
    """The paper's headline condition (paragraphs at 30 lux), by motion, against its figures."""
    group = [r for r in results if r.get("lux") == lux and r.get("kind") == kind]
    if not group:
        return [f"No {lux:g}-lux {kind} recordings in these results."]
    lines = [
        "| motion | n | darkread CER (mean) | median | worst | darkread WER | RGB CER | RGB WER |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    seated = [r for r in group if r.get("motion") in ("still", "normal")]
    rows = list(group_by(group, "motion").items()) + [("still + normal", seated), ("**all**", group)]
    for motion, members in rows:
        if not members:
            continue
        cers = [rate(r, "darkread") for r in members]
        worst = max((c for c in cers if c is not None), default=None)
        lines.append(
            f"| {motion} | {len(members)} | {_pct(mean(cers))} | {_pct(median(cers))} | {_pct(worst)} | "
            f"{_pct(mean(rate(r, 'darkread', 'wer') for r in members))} | {_pct(mean(rate(r, 'rgb') for r in members))} | "
            f"{_pct(mean(rate(r, 'rgb', 'wer') for r in members))} |"
        )

    def verdict(members: list[dict[str, Any]]) -> str:
        cer = mean(rate(r, "darkread") for r in members)
        side = "at or below" if cer is not None and cer <= PAPER_CER_30LUX else "above"
        return f"{_pct(cer)} over {len(members)} recordings, {side} the paper's {PAPER_CER_30LUX:.1%}"

    lines += ["", f"darkread's mean CER on {lux:g}-lux {kind}s: {verdict(group)} (WER {PAPER_WER_30LUX:.1%}; "
                  "GPT-4o on real recordings)."]
    if seated and len(seated) < len(group):
        lines[-1] += f" Reading still or with normal head motion: {verdict(seated)}; while walking it is harder."
    return lines


# -- bandwidth -------------------------------------------------------------------------------------


def bandwidth_rows(results: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r["bandwidth"] for r in results if isinstance(r.get("bandwidth"), dict) and "error" not in r["bandwidth"]]


def bandwidth_table(results: Sequence[dict[str, Any]]) -> list[str]:
    """Medians over recordings, per page (one recording) and per second, next to the paper's ratios."""
    rows = bandwidth_rows(results)
    if not rows:
        return ["No bandwidth figures in these results."]

    def med(get: Any) -> float | None:
        return median(get(b) for b in rows)

    def per_s(get: Any) -> float | None:
        return median(get(b) / b["duration_s"] for b in rows if b.get("duration_s"))

    png = med(lambda b: b["rgb"]["png"])
    lines = [
        (f"Medians over {len(rows)} recordings. A recording is one page; streams are also given per second. "
        f"The RGB snapshot is one full image of {_sizes(rows)} pixels."),
        "",
        "| what is sent | per page | per second | RGB PNG / this |",
        "|---|---:|---:|---:|",
    ]
    rgb_formats = [("raw", "RGB snapshot, uncompressed (8-bit x 3)"), ("png", "RGB snapshot, PNG")]
    rgb_formats += [(f"jpeg{q}", f"RGB snapshot, JPEG q{q}") for q in JPEG_QUALITIES]
    for key, label in rgb_formats:
        size = med(lambda b, k=key: b["rgb"].get(k))
        lines.append(f"| {label} | {_bytes(size)} | – | {_ratio(png / size) if png and size else '–'} |")
    streams = [
        ("evt3_bytes", "all events, EVT3"),
        ("foveated_evt3_bytes", "foveated events (100 x 200 window at the gaze), EVT3"),
        ("frame_stream_bytes", "binary frames as sent (Frame messages, mode `frames`)"),
        ("page_bytes", "stitched page as sent (one Page message, mode `pages`)"),
    ]
    for key, label in streams:
        page = med(lambda b, k=key: b.get(k))
        second = per_s(lambda b, k=key: b.get(k)) if key != "page_bytes" else None
        ref = second if key != "page_bytes" else page
        lines.append(f"| {label} | {_bytes(page)} | {_bytes(second) if second is not None else '–'} | "
                     f"{_ratio(png / ref) if png and ref else '–'} |")
    removed = med(lambda b: 1 - b["events_foveated"] / b["events"] if b["events"] else None)
    frames_vs_png = med(lambda b: b["rgb"]["png"] / (b["frame_stream_bytes"] / b["duration_s"]) if b["frame_stream_bytes"] else None)
    frames_vs_jpeg = med(lambda b: b["rgb"]["jpeg80"] / (b["frame_stream_bytes"] / b["duration_s"]) if b["frame_stream_bytes"] else None)
    page_vs_png = med(lambda b: b["rgb"]["png"] / b["page_bytes"] if b["page_bytes"] else None)
    page_vs_jpeg = med(lambda b: b["rgb"]["jpeg80"] / b["page_bytes"] if b["page_bytes"] else None)
    measured = sum(1 for b in rows if b.get("frames_measured"))
    lines += [
        "",
        "| figure | measured here (median) | paper |",
        "|---|---:|---:|",
        f"| events removed by foveation | {_pct(removed)} | ~{PAPER_FOVEATION_REMOVED:.0%} (real scenes) |",
        f"| one RGB image (PNG) / one second of binary frames | {_ratio(frames_vs_png)} | ~{PAPER_FRAMES_VS_RGB:.0f}x |",
        f"| one RGB image (JPEG q80) / one second of binary frames | {_ratio(frames_vs_jpeg)} | |",
        f"| one RGB image (PNG) / stitched page | {_ratio(page_vs_png)} | ~{PAPER_PAGE_VS_RGB:.0f}x |",
        f"| one RGB image (JPEG q80) / stitched page | {_ratio(page_vs_jpeg)} | |",
        "",
        (f"Frame figures measured on a real edge run for {measured} of {len(rows)} recordings (the rest: one "
        "frame per 1600 foveated events). Page bytes: the cloud-stitched page of the run, encoded as the "
        "`Page` message the glasses send in mode `pages`."),
    ]
    return lines


def _sizes(rows: Sequence[dict[str, Any]]) -> str:
    sizes = sorted({tuple(b["rgb_wh"]) for b in rows if b.get("rgb_wh")})
    return " or ".join(f"{w} x {h}" for w, h in sizes) if sizes else "unknown size"


# -- plots -----------------------------------------------------------------------------------------


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _lux_axis(ax: Any, levels: list[float]) -> None:
    """Log scale, darker to the right, a tick at every light level of the suite."""
    ax.set_xscale("log")
    if levels:
        ax.set_xticks(levels, [f"{v:g}" for v in levels])
        ax.minorticks_off()
    ax.invert_xaxis()


def plot_cer_vs(results: Sequence[dict[str, Any]], key: str, path: str | Path, *, xlabel: str, logx: bool = False,
                title: str = "") -> Path:
    """Mean CER per value of ``key`` for darkread and the RGB baseline, each recording as a faint dot."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=120)
    for (system, label), colour, marker in zip(SYSTEMS, ("tab:blue", "tab:orange"), ("o", "s")):
        xs, ys = [], []
        for value, group in group_by(results, key).items():
            m = mean(rate(r, system) for r in group)
            if value is not None and m is not None:
                xs.append(float(value))
                ys.append(m)
            pts = [(float(value), rate(r, system)) for r in group if value is not None and rate(r, system) is not None]
            if pts:
                ax.scatter(*zip(*pts), color=colour, alpha=0.25, s=14, marker=marker)
        if xs:
            ax.plot(xs, ys, marker=marker, color=colour, label=label)
    if logx:
        _lux_axis(ax, [float(v) for v in group_by(results, key) if v is not None])
    ax.set_xlabel(xlabel)
    ax.set_ylabel("character error rate (mean; dots: recordings)")
    ax.set_ylim(-0.03, 1.05)
    ax.yaxis.set_major_formatter(lambda v, _: f"{v:.0%}")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_cer_vs_lux_by_motion(results: Sequence[dict[str, Any]], path: str | Path) -> Path:
    """Two panels (darkread, RGB snapshot): mean CER vs lux, one line per motion level."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.6), dpi=120, sharey=True)
    colours = {"still": "tab:green", "normal": "tab:blue", "walking": "tab:red"}
    for ax, (system, label) in zip(axes, SYSTEMS):
        for motion, group in group_by(results, "motion").items():
            points = [(float(lux), mean(rate(r, system) for r in members))
                      for lux, members in group_by(group, "lux").items() if lux is not None]
            points = [(x, y) for x, y in points if y is not None]
            if points:
                ax.plot(*zip(*points), marker="o", label=str(motion), color=colours.get(str(motion)))
        _lux_axis(ax, [float(v) for v in group_by(results, "lux") if v is not None])
        ax.set_xlabel("illuminance at the page (lux, log scale)")
        ax.set_title(label, fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.yaxis.set_major_formatter(lambda v, _: f"{v:.0%}")
    axes[0].set_ylabel("character error rate (mean)")
    axes[0].set_ylim(-0.03, 1.05)
    axes[1].legend(title="motion", loc="best")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_backends(results: Sequence[dict[str, Any]], path: str | Path) -> Path | None:
    """Grouped bars: mean CER of each OCR engine on the stitched pages, by text kind."""
    names = backend_names(results)
    if not names:
        return None
    plt = _pyplot()
    groups = group_by(results, "kind")
    fig, ax = plt.subplots(figsize=(6.4, 3.8), dpi=120)
    width = 0.8 / len(names)
    for i, name in enumerate(names):
        values = [mean(rate(r, f"backends.{name}") for r in group) for group in groups.values()]
        xs = [k + (i - (len(names) - 1) / 2) * width for k in range(len(groups))]
        ax.bar(xs, [v if v is not None else 0 for v in values], width, label=name)
    ax.set_xticks(range(len(groups)), [str(k) for k in groups])
    ax.set_ylabel("character error rate (mean)")
    ax.yaxis.set_major_formatter(lambda v, _: f"{v:.0%}")
    ax.set_ylim(0, 1.05)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend()
    ax.set_title("OCR engines on the same stitched darkread pages", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_examples(
    results: Sequence[dict[str, Any]], path: str | Path, *, motion: str = "normal", kind: str = "paragraph"
) -> Path | None:
    """One row per lux level: the RGB snapshot crop next to the page darkread stitched (same scene);
    a ``kind`` recording with ``motion`` where there is one."""
    chosen = []
    for lux, group in sorted(group_by(results, "lux").items(), key=lambda kv: -float(kv[0] or 0)):
        pick = ([r for r in group if r.get("motion") == motion and r.get("kind") == kind]
                or [r for r in group if r.get("motion") == motion] or group)
        r = pick[0]
        crop, page = (r.get("rgb") or {}).get("crop_png"), (r.get("darkread") or {}).get("page_png")
        if crop and page and Path(crop).is_file() and Path(page).is_file():
            chosen.append((r, crop, page))
    if not chosen:
        return None
    plt = _pyplot()
    from PIL import Image

    fig, axes = plt.subplots(len(chosen), 2, figsize=(8.0, 1.7 * len(chosen)), dpi=120, squeeze=False)
    for row, (r, crop, page) in zip(axes, chosen):
        for ax, file, title in ((row[0], crop, f"RGB snapshot, CER {_pct(rate(r, 'rgb'))}"),
                                (row[1], page, f"darkread page, CER {_pct(rate(r, 'darkread'))}")):
            with Image.open(file) as image:
                ax.imshow(image.convert("L"), cmap="gray", vmin=0, vmax=255)
            ax.set_title(f"{r.get('lux', 0):g} lux, {r.get('motion')}: {title}", fontsize=8)
            ax.set_axis_off()
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


# -- the report ------------------------------------------------------------------------------------


def _camera_lines(results: Sequence[dict[str, Any]]) -> list[str]:
    lines = ["| lux | n | exposure | gain | paper signal | blur (median) |", "|---:|---:|---:|---:|---:|---:|"]
    for lux, group in group_by(results, "lux").items():
        snaps = [r["rgb"] for r in group if isinstance(r.get("rgb"), dict) and "blur_px" in r["rgb"]]
        if not snaps:
            continue
        lines.append(
            f"| {lux:g} | {len(snaps)} | {median(s['exposure_ms'] for s in snaps):.1f} ms | {median(s['gain'] for s in snaps):.1f} | "
            f"{median(s['paper_electrons'] for s in snaps):.0f} e- | {median(s['blur_px'] for s in snaps):.1f} px |"
        )
    return lines


def _per_recording(results: Sequence[dict[str, Any]]) -> list[str]:
    lines = [
        "| recording | lux | motion | kind | font | x-h | darkread CER | RGB CER | darkread text |",
        "|---|---:|---|---|---|---:|---:|---:|---|",
    ]
    for r in results:
        d = r.get("darkread") or {}
        text = d.get("text") if "text" in d else f"error: {d.get('error', '?')}"
        text = (text or "").replace("\n", " / ").replace("|", "\\|")
        text = text if len(text) <= 60 else text[:57] + "..."
        font = f"{r.get('font')}{' (held out)' if r.get('held_out_font') else ''}"
        lines.append(
            f"| {r.get('name')} | {r.get('lux', 0):g} | {r.get('motion')} | {r.get('kind')} | {font} | "
            f"{r.get('xheight_px', 0):g} | {_pct(rate(r, 'darkread'))} | {_pct(rate(r, 'rgb'))} | {text} |"
        )
    return lines


def _errors(results: Sequence[dict[str, Any]]) -> list[str]:
    out = []
    for r in results:
        for section in ("darkread", "rgb", "backends", "bandwidth"):
            value = r.get(section)
            if isinstance(value, dict) and "error" in value:
                out.append(f"- {r.get('name')}: {section}: {value['error']}")
            elif section == "backends" and isinstance(value, dict):
                out += [f"- {r.get('name')}: OCR engine {name}: {v['error']}" for name, v in value.items()
                        if isinstance(v, dict) and "error" in v]
    return out


def write_report(results: Sequence[dict[str, Any]], out_dir: str | Path, info: ReportInfo) -> Path:
    """Write ``README.md``, ``results.json`` and the PNG plots into ``out_dir``; returns the Markdown path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results = sorted(results, key=lambda r: str(r.get("name")))
    plot_cer_vs(results, "lux", out / "cer_vs_lux.png", xlabel="illuminance at the page (lux, log scale)", logx=True,
                title="CER vs light: darkread and one RGB snapshot")
    sizes, sizes_label = sweep_subset(results, "xheight_px")
    plot_cer_vs(sizes, "xheight_px", out / "cer_vs_xheight.png", xlabel="x-height (event-camera pixels)",
                title=f"CER vs text size ({sizes_label})")
    plot_cer_vs_lux_by_motion(results, out / "cer_vs_lux_by_motion.png")
    backends_png = plot_backends(results, out / "ocr_backends_by_kind.png")
    examples_png = plot_examples(results, out / "examples.png")
    (out / RESULTS_NAME).write_text(json.dumps(results, indent=1))

    dk, rgb = mean(rate(r, "darkread") for r in results), mean(rate(r, "rgb") for r in results)
    md = [
        "# darkread evaluation",
        "",
        f"- date: {info.date}",
        f"- commit: `{info.commit}`" + _run_commits(results, info.commit),
        f"- OCR backend (darkread and the RGB baseline): `{info.backend}`",
        f"- reconstruction model: {info.model or 'the shipped default'}",
        f"- suite: {info.suite or f'{len(results)} recordings'}",
        *[f"- {note}" for note in info.notes],
        "",
        (f"Over all {len(results)} recordings: darkread mean CER {_pct(dk)} (WER {_pct(mean(rate(r, 'darkread', 'wer') for r in results))}), "
        f"RGB snapshot mean CER {_pct(rgb)} (WER {_pct(mean(rate(r, 'rgb', 'wer') for r in results))}). "
        "CER/WER: jiwer after NFKC and whitespace collapse; case and punctuation count; per-recording rates "
        "clipped at 100 % before averaging. The paper reports CER 2.5 % / WER 8.3 % at 30 lux with GPT-4o "
        "on real recordings; these are synthetic recordings read with the offline engine."),
        "",
        "## Paragraphs at 30 lux (the paper's headline)",
        "",
        *headline_table(results),
        "",
        "## CER vs light",
        "",
        "![CER vs lux](cer_vs_lux.png)",
        "",
        *grouped_table(results, "lux", "lux", lambda v: f"{v:g}"),
        "",
        "By motion (left darkread, right the RGB snapshot: exposure lengthens as light falls, so motion blur grows):",
        "",
        "![CER vs lux by motion](cer_vs_lux_by_motion.png)",
        "",
        *([("What the OCR saw, one paragraph recording with normal head motion per light level (left: the RGB "
           "snapshot's page crop; right: the page darkread stitched from binary frames):"), "", "![examples](examples.png)", ""]
          if examples_png else []),
        "## By motion, text kind, font and x-height",
        "",
        *grouped_table(results, "motion", "motion"),
        "",
        "Light and motion together (the RGB snapshot suffers from motion blur, darkread does not expose):",
        "",
        *grouped_table(results, ("lux", "motion"), "lux, motion", lambda v: f"{v[0]:g}, {v[1]}"),
        "",
        *grouped_table(results, "kind", "text kind"),
        "",
        *grouped_table(results, "font", "font", lambda v: f"{v} (held out of training)" if v in _held_out(results) else str(v)),
        "",
        "![CER vs x-height](cer_vs_xheight.png)",
        "",
        f"Text size, {sizes_label}:",
        "",
        *grouped_table(sizes, "xheight_px", "x-height (px)", lambda v: f"{v:g}"),
        "",
        "## OCR engines on the stitched pages",
        "",
        ("Each engine reads the same page image darkread stitched (offline engines; remote ones only when "
        "configured through `DARKREAD_*` settings)."),
        "",
        *backend_table(results),
        "",
        *(["![OCR engines by text kind](ocr_backends_by_kind.png)", ""] if backends_png else []),
        "## Bandwidth",
        "",
        *bandwidth_table(results),
        "",
        "## The RGB baseline",
        "",
        ("One snapshot of the same synthetic scene from the glasses' RGB camera, taken in the middle of the "
        "recording and read by the same OCR engine after cropping the region around the page "
        "(`models/synth/rgb_camera.py`, read by `darkread/eval/rgb_baseline.py`): 2880 x 2880 rectified pinhole at 26 px/deg; auto-exposure "
        "metered on the paper, lengthening up to 1/30 s, then analogue gain up to 16x; motion blur from "
        "the session's head and page motion during the exposure; lens blur (sigma 1 px); an RGGB Bayer "
        "mosaic with Poisson shot noise (about 100 e-/s per lux on white paper per photosite), 2.5 e- "
        "read noise, bilinear demosaicing, sRGB, 8 bits; JPEG q90 as the glasses store frames; no ISP "
        "denoising. Recordings that were not made by `darkread eval make-suite` (real ones) use their own "
        "`rgb.png`, read whole."),
        "",
        *_camera_lines(results),
        "",
        "## Reading these numbers",
        "",
        ("- The recordings are synthetic (`darkread.models.synth`): one printed page, a reading scanpath, "
        "head and page motion, a low-light event sensor model. Only the part of the sensor the gaze can "
        "reach sees the page; the rest of the sensor produces noise events only, so foveation removes a "
        "smaller share of events than on real scenes, where the whole field of view is textured (the "
        "paper's ~98 %)."),
        ("- The RGB baseline leans to the best case: exposure metered on the page, the crop around the page "
        "handed to the OCR, no ISP denoising smear, no rolling shutter. Its failures come from motion blur "
        "and noise."),
        ("- Both readers use the same OCR: `local` is the embedded engine (rapidocr) followed by the dictionary "
        "correction of lookalike glyphs on prose lines (`cloud/ocr/lexicon.py`); the engine comparison above "
        "lists each engine with it and without it (`-raw`)."),
        ("- Each recording ends once the page has been read (no re-reading); `paragraph` and `words` texts "
        "come from the part of the corpus never used for training, and the held-out font family was never "
        "seen in training."),
        ("- x-heights are in event-camera pixels at the start of a recording; the RGB camera's resolution "
        "per degree is about the same (26 vs ~25.6 px/deg)."),
        "",
        "## Per recording",
        "",
        *_per_recording(results),
        "",
    ]
    errors = _errors(results)
    if errors:
        md += ["## Failures", "", *errors, ""]
    path = out / REPORT_NAME
    path.write_text("\n".join(md))
    return path


def _held_out(results: Sequence[dict[str, Any]]) -> set[str]:
    return {str(r.get("font")) for r in results if r.get("held_out_font")}


def _run_commits(results: Sequence[dict[str, Any]], report_commit: str) -> str:
    """When the recordings were evaluated at other commits than the report's, say which and when."""
    commits = sorted({str(r["commit"]) for r in results if r.get("commit")})
    if not commits or commits == [report_commit]:
        return ""
    stamps = sorted(str(r["evaluated"]) for r in results if r.get("evaluated"))
    span = f", {stamps[0]} to {stamps[-1]}" if stamps else ""
    return f" (recordings evaluated at {', '.join(f'`{c}`' for c in commits)}{span})"

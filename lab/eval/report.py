"""The evaluation report: the Markdown page that puts the tables and figures together.

Input is the per-recording results ``runner.evaluate_recording`` stores, typed by
``darkread.lab.eval.results``; nothing here runs a model, so a report can be rebuilt, or tested, from
stored results alone. The work is split by what it does: ``aggregate`` (means, groups, sweeps),
``tables`` (Markdown tables), ``plots`` (figures) and ``provenance`` (how the report was made).
Means of CER/WER clip each recording's rate at 1.0 (insertions can push a rate above 1, which
would let one garbage read dominate).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from darkread.cloud.confidence import load_model as load_confidence_model
from darkread.lab.eval.aggregate import held_out_fonts, mean, paired, sweep_subset
from darkread.lab.eval.attribution import attribution_section
from darkread.lab.eval.before_after import before_after_section
from darkread.lab.eval.clean_text import clean_text_check, clean_text_section
from darkread.lab.eval.evidence import evidence_section
from darkread.lab.eval.plots import plot_backends, plot_cer_vs, plot_cer_vs_lux_by_motion, plot_examples
from darkread.lab.eval.provenance import ReportInfo, run_commits
from darkread.lab.eval.results import RecordingResult
from darkread.lab.eval.selective import selective_section
from darkread.lab.eval.simulators import simulator_section
from darkread.lab.eval.tables import (
    backend_table,
    bandwidth_table,
    camera_table,
    failure_lines,
    grouped_table,
    headline_table,
    mode_headline,
    mode_table,
    pct,
    per_recording_table,
    scanpath_table,
)

REPORT_NAME = "README.md"
RESULTS_NAME = "results.json"


PATH_KEYS = frozenset({"page_png", "crop_png", "recording"})  # the fields of a result that name files


def relative_paths(value: Any, suite_dir: Path, key: str | None = None) -> Any:
    """``value`` (a result's JSON) with its file paths written relative to the suite: a committed
    report must not carry the directories of the machine that made it.

    Only the fields that name files (``PATH_KEYS``) are rewritten, whatever they hold: a text read
    off a page may well start with "/". Error messages keep their words, with the suite's absolute
    directory taken out of them. Paths that already are relative (results made so, or rewritten
    before) stay as they are."""
    if isinstance(value, dict):
        return {k: relative_paths(v, suite_dir, k) for k, v in value.items()}
    if isinstance(value, list):
        return [relative_paths(v, suite_dir, key) for v in value]
    if not isinstance(value, str):
        return value
    if key in PATH_KEYS and os.path.isabs(value):
        return os.path.relpath(value, suite_dir)
    if key == "error":
        return value.replace(f"{suite_dir}{os.sep}", "")
    return value


def _results_json(results: Sequence[RecordingResult], suite_dir: str | Path | None) -> str:
    raws = [r.raw for r in results]
    return json.dumps(raws if suite_dir is None else relative_paths(raws, Path(suite_dir).resolve()), indent=1)


def write_report(results: Sequence[RecordingResult], out_dir: str | Path, info: ReportInfo,
                 beside: Sequence[RecordingResult] | None = None, suite_dir: str | Path | None = None,
                 before: tuple[str, Sequence[RecordingResult]] | None = None) -> Path:
    """Write ``README.md``, ``results.json`` and the PNG plots into ``out_dir``; returns the Markdown path.

    ``beside``: the same suite evaluated in the other edge mode, compared with ``results`` (the primary
    mode, which every other table shows) in a section of its own and in the bandwidth table.
    ``suite_dir``: the paths in the JSON files are written relative to it. ``before``: (where from,
    results) of an earlier evaluation of the same suite, compared on the recordings both hold."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    every = sorted(results, key=lambda r: str(r.name))
    results = [r for r in every if r.scanpath == "model"]  # the tables below: the reading model's scanpaths
    human = [r for r in every if r.scanpath != "model"]
    other = sorted((r for r in beside or () if r.scanpath == "model"), key=lambda r: str(r.name))
    modes_md = _modes_section(results, other, out) if beside is not None else []
    if beside is not None:
        (out / f"results_{_mode(beside)}.json").write_text(_results_json(beside, suite_dir))
    plot_cer_vs(results, "lux", out / "cer_vs_lux.png", xlabel="illuminance at the page (lux, log scale)", logx=True,
                title="CER vs light: darkread and one RGB snapshot")
    sizes, sizes_label = sweep_subset(results, "xheight_px")
    plot_cer_vs(sizes, "xheight_px", out / "cer_vs_xheight.png", xlabel="x-height (event-camera pixels)",
                title=f"CER vs text size ({sizes_label})")
    plot_cer_vs_lux_by_motion(results, out / "cer_vs_lux_by_motion.png")
    backends_png = plot_backends(results, out / "ocr_backends_by_kind.png")
    examples_png = plot_examples(results, out / "examples.png")
    (out / RESULTS_NAME).write_text(_results_json(every, suite_dir))

    dk, rgb = mean(r.rate("darkread") for r in results), mean(r.rate("rgb") for r in results)
    md = [
        "# darkread evaluation",
        "",
        f"- date: {info.date}",
        f"- commit: `{info.commit}`" + run_commits(results, info.commit),
        f"- OCR backend (darkread and the RGB baseline): `{info.backend}`",
        f"- reconstruction model: {info.model or 'the shipped default'}",
        f"- suite: {info.suite or f'{len(results)} recordings'}",
        f"- edge mode: `{_mode(every)}`" + (f" (`{_mode(beside)}` beside it: {len(beside)} recordings)" if beside else ""),
        *[f"- {note}" for note in info.notes],
        "",
        (f"Over all {len(results)} recordings: darkread mean CER {pct(dk)} (WER {pct(mean(r.rate('darkread', 'wer') for r in results))}), "
        f"RGB snapshot mean CER {pct(rgb)} (WER {pct(mean(r.rate('rgb', 'wer') for r in results))}). "
        "CER/WER: jiwer after NFKC and whitespace collapse; case and punctuation count; per-recording rates "
        "clipped at 100 % before averaging. The paper reports CER 2.5 % / WER 8.3 % at 30 lux with GPT-4o "
        "on real recordings; these are synthetic recordings read with the offline engine."),
        "",
        "## Paragraphs at 30 lux (the paper's headline)",
        "",
        *headline_table(results),
        "",
        *modes_md,
        *(before_after_section(results, before[1], before[0]) if before else []),
        *selective_section(every, out, load_confidence_model()),
        *clean_text_section(clean_text_check()),
        "## Real readers' scanpaths",
        "",
        *scanpath_table(results, human),
        "",
        "## CER vs light",
        "",
        "![CER vs lux](cer_vs_lux.png)",
        "",
        *grouped_table(results, "lux", "lux", lambda v: f"{v:g}"),
        "",
        *simulator_section(out),
        *attribution_section(out),
        *evidence_section(out),
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
        *grouped_table(results, "font", "font", lambda v: f"{v} (held out of training)" if v in held_out_fonts(results) else str(v)),
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
        *bandwidth_table(results, [q for _, q in paired(results, other)]),  # the other mode on the same recordings
        "",
        "## The RGB baseline",
        "",
        ("One snapshot of the same synthetic scene from the glasses' RGB camera, taken in the middle of the "
        "recording and read by the same OCR engine after cropping the region around the page "
        "(`lab/synth/rgb_camera.py`, read by `lab/eval/rgb_baseline.py`): 2880 x 2880 rectified pinhole at 26 px/deg; auto-exposure "
        "metered on the paper, lengthening up to 1/30 s, then analogue gain up to 16x; motion blur from "
        "the session's head and page motion during the exposure; lens blur (sigma 1 px); an RGGB Bayer "
        "mosaic with Poisson shot noise (about 100 e-/s per lux on white paper per photosite), 2.5 e- "
        "read noise, bilinear demosaicing, sRGB, 8 bits; JPEG q90 as the glasses store frames; no ISP "
        "denoising. Recordings that were not made by `darkread eval make-suite` (real ones) use their own "
        "`rgb.png`, read whole."),
        "",
        *camera_table(results),
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
        *per_recording_table(results),
        "",
    ]
    errors = failure_lines(results)
    if errors:
        md += ["## Failures", "", *errors, ""]
    path = out / REPORT_NAME
    path.write_text("\n".join(md))
    return path


def _mode(results: Sequence[RecordingResult]) -> str:
    """The edge mode(s) a run was evaluated in."""
    return ", ".join(sorted({r.infer for r in results})) or "–"


def _modes_section(results: Sequence[RecordingResult], beside: Sequence[RecordingResult], out: Path) -> list[str]:
    """Both edge modes on the recordings both evaluated: CER by light and motion, the 30-lux headline, a plot."""
    pairs = paired(results, beside)
    first, second = _mode(results), _mode(beside)
    md = ["## Edge modes side by side", "",
          (f"darkread with the edge in `{first}` mode (every other table of this report) and in `{second}` mode, on the "
           f"{len(pairs)} recordings both runs evaluated (`darkread eval run --infer both`, or `--beside` a stored run). "
           "every-window infers every 1600-event window and sends every frame; on-change infers when the view "
           "changed during a fixation and sends one fused view per fixation. Difference in percentage points: "
           "positive when the first mode reads worse."), ""]
    if not pairs:
        return [*md, "No recording was evaluated in both modes.", ""]
    plot_cer_vs(results, "lux", out / "cer_vs_lux_modes.png", xlabel="illuminance at the page (lux, log scale)",
                logx=True, title=f"CER vs light: darkread in both edge modes ({len(pairs)} recordings)",
                series=[(f"darkread, {first}", [p for p, _ in pairs], "darkread"),
                        (f"darkread, {second}", [q for _, q in pairs], "darkread"),
                        ("RGB snapshot baseline", [p for p, _ in pairs], "rgb")])
    return [*md, *mode_headline(pairs), "", "![CER vs lux, both modes](cer_vs_lux_modes.png)", "",
            *mode_table(pairs, ("lux", "motion"), "lux, motion", lambda v: f"{v[0]:g}, {v[1]}"), "",
            *mode_table(pairs, "lux", "lux", lambda v: f"{v:g}"), ""]

"""Before/after: the shipped network next to a fine-tuned one on recordings it was not tuned on.

Two figures per input, for each model:

* **ink F1** of the windows the glasses would cut (gaze -> fovea -> 1600 events -> deblur ->
  in dim light denoise -> voxel grid),
  against the simulator's ground truth: the page's ink under its true pose (``pose_truth.npz``
  with ``page.layout.json`` for a marker page or ``page_ink.npz`` for a plain one, what
  ``synth recording`` writes). A shard directory
  (``darkread synth dataset``, or ``train annotate``'s output) is scored on its own targets.
* **end-to-end CER**: the recording read exactly as ``darkread read --model`` reads it (a real edge
  and cloud on loopback, the page stitched and read by OCR) against its ``text.txt``.

With placebos (``--placebos N``: the base's weights perturbed, nothing learned) the report gives
the range chance alone moves each figure over, and where the tuned model falls against it.

Predictions run on onnxruntime (what ships). Every read is cached under ``OUT/cache/<model
digest>/`` so an interrupted comparison resumes, and the shipped model's reads are shared between
comparisons of several tuned models.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from darkread.lab.eval.provenance import model_digest
from darkread.lab.jobs import run_jobs
from darkread.lab.truth import ScoredWindows, is_recording, truth_windows
from darkread.models.train.data import load_dataset
from darkread.models.train.evaluate import predict_onnx
from darkread.models.train.ink_scores import ink_counts, scores_from_counts
from darkread.read import read_recording

log = logging.getLogger(__name__)

RESULTS_NAME = "compare.json"
REPORT_NAME = "compare.md"
PLOT_NAME = "compare.png"


def shard_windows(directory: str | Path, limit: int | None = None) -> ScoredWindows:

    data = load_dataset(directory, limit=limit)
    return ScoredWindows(data.voxels, data.targets, "shard targets", data.ignore)


def ink_f1(model: str | Path, scored: ScoredWindows) -> dict[str, Any] | None:
    """Pooled ink counts and F1 of ``model`` on the windows (None without ground truth)."""

    if scored.targets is None or len(scored.voxels) == 0:
        return None
    pred = predict_onnx(model, scored.voxels).astype(bool)
    truth = scored.targets.astype(bool)
    if scored.ignore is not None:
        valid = scored.ignore == 0
        pred, truth = pred[valid], truth[valid]
    tp, fp, fn = ink_counts(pred, truth)
    return {"tp": tp, "fp": fp, "fn": fn, "windows": len(pred), **{k: round(v, 4) for k, v in scores_from_counts(tp, fp, fn).items()}}


def read_cer(model: str | Path, recording: str | Path, backend: str, cache_dir: Path) -> dict[str, Any]:
    """``darkread read --model`` on the recording (cached per model digest and recording name)."""

    cache = cache_dir / f"{Path(recording).name}.json"
    if cache.is_file():
        return json.loads(cache.read_text())
    result = read_recording(recording, backend=backend, model=str(model))
    row = {"cer": result.cer, "wer": result.wer, "text": result.text, "reference": result.reference, "frames": result.frames,
           "seconds": round(result.seconds, 1)}
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps(row, indent=1) + "\n", encoding="utf-8")
    return row


def recording_meta(path: Path) -> dict[str, Any]:
    meta_path = path / "meta.json"
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    return {"lux": meta.get("lux"), "font": meta.get("font"), "regime": meta.get("sensor_regime", "standard")}


def compare(
    inputs: Sequence[str | Path],
    models: dict[str, Path],
    out: str | Path,
    *,
    read: bool = True,
    backend: str = "local",
    group: str | None = None,
    chance: Sequence[str] = (),
    jobs: int = 1,
    progress: bool = True,
) -> dict[str, Any]:
    """Score every input with every model (name -> ONNX); writes OUT/compare.json, .md and .png.

    ``chance`` names the models among ``models`` that are placebos (``placebo.write_placebo``): the
    report gives their spread beside the other two, and says where the tuned model falls against it.
    ``jobs`` inputs are scored at once, each in its own process; the rows keep the inputs' order.
    """
    from tqdm import tqdm

    out = Path(out)
    digests = {name: model_digest(path) for name, path in models.items()}
    items = [Path(p) for p in inputs]

    bar = tqdm(total=len(items), desc="comparing", unit="input", disable=not progress)
    task = partial(score_input, models=models, digests=digests, out=out, read=read, backend=backend, group=group)
    rows = run_jobs(task, items, jobs, bar.update)
    bar.close()
    names = [n for n in models if n not in chance]
    report = {"models": {n: {"path": str(p), "sha256_12": digests[n]} for n, p in models.items()},
              "chance": list(chance), "backend": backend, "rows": rows, "summary": summarise(rows, names, list(chance))}
    out.mkdir(parents=True, exist_ok=True)
    (out / RESULTS_NAME).write_text(json.dumps(report, indent=1, default=float) + "\n", encoding="utf-8")
    (out / REPORT_NAME).write_text(markdown(report), encoding="utf-8")
    plot(report, out / PLOT_NAME)
    return report


def score_input(item: Path, models: dict[str, Path], digests: dict[str, str], out: Path, *, read: bool, backend: str,
                group: str | None) -> dict[str, Any]:
    """One input's row: ink F1 of every model and, for a recording, every model's end-to-end read."""
    recording = is_recording(item)
    row: dict[str, Any] = {"input": item.name, "path": str(item), "kind": "recording" if recording else "shards",
                           **(recording_meta(item) if recording else {}), "group": group}
    # (a recording's windows cut as the edge cuts them: deblurred, in dim light denoised)
    scored = truth_windows(item, deblur=True, denoise=True) if recording else shard_windows(item)
    row["truth"] = scored.source
    for name, path in models.items():
        row[name] = {"ink": ink_f1(path, scored)}
        if recording and read:
            row[name]["read"] = read_cer(path, item, backend, out / "cache" / digests[name])
    log.info("%s: %s", item.name, {n: (row[n]["ink"] or {}).get("f1") for n in models})
    return row


def group_key(row: dict[str, Any]) -> str:
    if row.get("group"):
        return str(row["group"])
    if row["kind"] == "shards":
        return row["input"]
    lux = row.get("lux")
    return f"{row.get('regime') or 'recordings'} {lux:g} lux" if lux is not None else str(row.get("regime") or "recordings")


def summarise(rows: list[dict[str, Any]], names: list[str], chance: Sequence[str] = ()) -> list[dict[str, Any]]:
    """Per group: pooled ink F1 and mean CER of each model, how many recordings the second of ``names``
    improved, and with placebos (``chance``) their range and where the second model falls against it."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(group_key(row), []).append(row)
    summary = []
    for key, members in groups.items():
        entry: dict[str, Any] = {"group": key, "n": len(members)}
        for name in [*names, *chance]:
            inks = [m[name]["ink"] for m in members if m[name].get("ink")]
            if inks:
                tp, fp, fn = (sum(i[k] for i in inks) for k in ("tp", "fp", "fn"))
                entry[f"{name}_ink_f1"] = round(scores_from_counts(tp, fp, fn)["f1"], 4)
                entry["windows"] = sum(i["windows"] for i in inks)
            cers = [m[name]["read"]["cer"] for m in members if m[name].get("read") and m[name]["read"].get("cer") is not None]
            if cers:
                entry[f"{name}_cer"] = round(float(np.mean(cers)), 4)
        if len(names) == 2:
            a, b = names
            pairs = [(m[a]["read"]["cer"], m[b]["read"]["cer"]) for m in members
                     if m[a].get("read") and m[b].get("read") and m[a]["read"].get("cer") is not None and m[b]["read"].get("cer") is not None]
            if pairs:
                entry["cer_lower"] = sum(y < x for x, y in pairs)
                entry["cer_higher"] = sum(y > x for x, y in pairs)
        for key_ in ("ink_f1", "cer"):
            spread = [entry[f"{c}_{key_}"] for c in chance if f"{c}_{key_}" in entry]
            if spread:
                entry[f"chance_{key_}"] = [min(spread), max(spread)]
                if len(names) == 2 and f"{names[1]}_{key_}" in entry:
                    entry[f"{names[1]}_{key_}_against_chance"] = against_chance(entry[f"{names[1]}_{key_}"], spread)
        summary.append(entry)
    return summary


def against_chance(value: float, spread: Sequence[float]) -> str:
    """Where ``value`` lies against the placebos' values: "below" the lowest, "above" the highest, or "inside"."""
    if value < min(spread):
        return "below"
    return "above" if value > max(spread) else "inside"


def _fmt(value: Any, pct: bool = False) -> str:
    if value is None:
        return "-"
    return f"{100 * value:.1f} %" if pct else f"{value:.3f}"


def _fmt_range(spread: Sequence[float] | None, pct: bool = False) -> str:
    return "-" if not spread else f"{_fmt(spread[0], pct)} – {_fmt(spread[1], pct)}"


def markdown(report: dict[str, Any]) -> str:
    chance = list(report.get("chance", []))
    names = [n for n in report["models"] if n not in chance]
    lines = ["# Before/after (`darkread train compare`)", ""]
    lines += [f"* `{n}`: `{m['path']}` (sha256 {m['sha256_12']})" for n, m in report["models"].items() if n not in chance]
    if chance:
        lines.append(f"* {len(chance)} placebos (`darkread train placebo`: the base's weights perturbed, nothing learned) give "
                     "the spread chance alone moves the figures over; a change means something only outside it")
    lines += [f"* OCR backend: {report['backend']}; ink F1 pooled over the windows of a group, CER averaged over its recordings", ""]
    spread_head = [f"ink F1 {len(chance)} placebos"] if chance else []
    head = ["group", "n", "windows", *[f"ink F1 {n}" for n in names], *spread_head, *[f"CER {n}" for n in names],
            *([f"CER {len(chance)} placebos", f"{names[-1]} against them"] if chance else [])]
    if len(names) == 2:
        head.append(f"CER lower / higher with {names[1]}")
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for s in report["summary"]:
        cells = [s["group"], str(s["n"]), str(s.get("windows", "-")), *[_fmt(s.get(f"{n}_ink_f1")) for n in names]]
        if chance:
            cells.append(_fmt_range(s.get("chance_ink_f1")))
        cells += [_fmt(s.get(f"{n}_cer"), pct=True) for n in names]
        if chance:
            cells += [_fmt_range(s.get("chance_cer"), pct=True), s.get(f"{names[-1]}_cer_against_chance", "-")]
        if len(names) == 2:
            cells.append(f"{s['cer_lower']} / {s['cer_higher']}" if "cer_lower" in s else "-")
        lines.append("| " + " | ".join(cells) + " |")
    per_input = [*[f"ink F1 {n}" for n in names], *[f"CER {n}" for n in names], *([f"CER {len(chance)} placebos"] if chance else [])]
    lines += ["", "Per input:", "", "| input | " + " | ".join(per_input) + " |", "|---|" + "---|" * len(per_input)]
    for r in report["rows"]:
        f1 = [_fmt((r[n]["ink"] or {}).get("f1")) for n in names]
        cer = [_fmt((r[n].get("read") or {}).get("cer"), pct=True) for n in names]
        if chance:
            reads = [r[c]["read"]["cer"] for c in chance if (r[c].get("read") or {}).get("cer") is not None]
            cer.append(_fmt_range([min(reads), max(reads)] if reads else None, pct=True))
        lines.append(f"| {r['input']} | " + " | ".join(f1 + cer) + " |")
    return "\n".join(lines) + "\n"


def plot(report: dict[str, Any], path: Path) -> Path:
    """Grouped bars: ink F1 and CER per group, one bar per model."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    chance = list(report.get("chance", []))
    names = [n for n in report["models"] if n not in chance]
    summary = report["summary"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
    x = np.arange(len(summary))
    width = 0.8 / max(1, len(names))
    for ax, key, title in ((axes[0], "ink_f1", "ink F1 (higher is better)"), (axes[1], "cer", "CER (lower is better)")):
        for k, name in enumerate(names):
            values = [s.get(f"{name}_{key}") for s in summary]
            ax.bar(x + (k - (len(names) - 1) / 2) * width, [v if v is not None else 0 for v in values], width, label=name)
        spans = [(i, s[f"chance_{key}"]) for i, s in enumerate(summary) if s.get(f"chance_{key}")]
        if spans:  # the placebos' range across the group's bars: what chance alone gives
            for i, (low, high) in spans:
                ax.fill_between([i - 0.45, i + 0.45], low, high, color="0.3", alpha=0.35, lw=0,
                                label=f"{len(chance)} placebos" if i == spans[0][0] else None)
        ax.set_xticks(x, [s["group"] for s in summary], rotation=20, fontsize=8, ha="right")
        ax.set_title(title, fontsize=9)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path

"""Several evaluated suites of the same scenes side by side: ``darkread eval side-by-side``.

Suites made by ``darkread eval make-suite`` with the same selection hold recordings of the same
names, and a name fixes the scene, text, gaze and seed; what differs between two suites is what made
their events (the sensor regime, its biases, the photoreceptor's K, the head motion's draws). So
each row here compares the suites on the recordings they all hold at that condition, one column of
mean CER per suite, with the difference to a reference suite when one is named, the RGB snapshot of
the first suite that has one beside, and a plot of CER against light.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from darkread.lab.eval.aggregate import group_by, mean
from darkread.lab.eval.plots import _pyplot
from darkread.lab.eval.results import RecordingResult
from darkread.lab.eval.runner import load_results
from darkread.lab.eval.tables import pct


@dataclass(frozen=True)
class LabelledSuite:
    """One evaluated suite under a label: its results by recording name (real-reader recordings left out)."""

    label: str
    results: dict[str, RecordingResult]

    @classmethod
    def load(cls, spec: str, mode: str) -> LabelledSuite:
        """``LABEL=SUITE_DIR`` (results in ``SUITE_DIR/eval_runs/<mode>``) or ``LABEL=SUITE_DIR:WORK_DIR``."""
        label, sep, where = spec.partition("=")
        if not sep or not label or not where:
            raise ValueError(f"{spec!r}: give each suite as LABEL=SUITE_DIR (e.g. dark=runs/s48/central_dark)")
        suite, _, work = where.partition(":")
        folder = Path(work) if work else Path(suite) / "eval_runs" / mode
        if not folder.is_dir():
            raise FileNotFoundError(f"{folder}: no evaluation here; run `darkread eval run {suite} --infer {mode}` first")
        results = {str(r.name): r for r in load_results(folder) if r.scanpath == "model" and r.darkread is not None}
        if not results:
            raise FileNotFoundError(f"{folder}: no stored results; run `darkread eval run {suite} --infer {mode}` first")
        return cls(label, results)


def _common(suites: Sequence[LabelledSuite], names: set[str]) -> list[str]:
    """The names every suite holding any of ``names`` holds (the recordings a row compares)."""
    holding = [s for s in suites if names & s.results.keys()]
    common = set(names)
    for s in holding:
        common &= s.results.keys()
    return sorted(common)


def _cer(suite: LabelledSuite, names: Sequence[str]) -> float | None:
    return mean(suite.results[n].rate("darkread", "cer") for n in names) if names and names[0] in suite.results else None


def _rgb(suites: Sequence[LabelledSuite], names: Sequence[str]) -> float | None:
    for s in suites:
        if names and names[0] in s.results:
            value = mean(s.results[n].rate("rgb", "cer") for n in names)
            if value is not None:
                return value
    return None


def _signed(a: float | None, b: float | None) -> str:
    return "–" if a is None or b is None else f"{100 * (a - b):+.1f}"


def cer_rows(suites: Sequence[LabelledSuite], key: str | tuple[str, ...], label: str,
             reference: str | None = None) -> list[str]:
    """A Markdown table: per value of ``key``, the recordings compared, each suite's mean CER (and its
    difference to ``reference`` in points), and the RGB snapshot's."""
    ref = next((s for s in suites if s.label == reference), None)
    others = [s for s in suites if s is not ref]
    head = [f"{label}", "n", *[s.label for s in suites], *[f"{s.label} − {ref.label} (points)" for s in others if ref], "RGB"]
    rows = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 1)]
    everything = [r for s in suites for r in s.results.values()]
    for value, group in group_by(everything, key).items():
        names = _common(suites, {str(r.name) for r in group})
        if not names:
            continue
        shown = ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in (value if isinstance(value, tuple) else (value,)))
        cells = [shown, str(len(names)), *[pct(_cer(s, names)) for s in suites]]
        if ref is not None:
            cells += [_signed(_cer(s, names), _cer(ref, names)) for s in others]
        cells.append(pct(_rgb(suites, names)))
        rows.append("| " + " | ".join(cells) + " |")
    return rows


def plot_cer_vs_lux(suites: Sequence[LabelledSuite], path: Path, title: str) -> Path:
    """Mean CER against light, one line per suite (each on every recording it holds at that light)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for s in suites:
        groups = group_by(list(s.results.values()), "lux")
        lux = [float(v) for v in groups]
        cer = [100 * (mean(r.rate("darkread", "cer") for r in g) or 0.0) for g in groups.values()]
        ax.plot(lux, cer, "o-", label=s.label)
    ax.set_xscale("log")
    ax.set_xlabel("light at the page (lux)")
    ax.set_ylabel("mean CER (%)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_side_by_side(suites: Sequence[LabelledSuite], out: Path, *, title: str, reference: str | None = None,
                       notes: Sequence[str] = (), command: str = "") -> Path:
    """``out`` (a .md file): CER by light and by light and motion, the plot beside it (same stem, .png)."""
    labels = [s.label for s in suites]
    if len(set(labels)) != len(labels):
        raise ValueError(f"labels must differ: {', '.join(labels)}")
    if reference is not None and reference not in labels:
        raise ValueError(f"--reference {reference!r}: not one of the labels {', '.join(labels)}")
    out.parent.mkdir(parents=True, exist_ok=True)
    plot = plot_cer_vs_lux(suites, out.with_suffix(".png"), title)
    md: list[Any] = [f"# {title}", ""]
    if command:
        md += ["Reproduce:", "", f"    {command}", ""]
    md += [*notes, ""] if notes else []
    md += ["Each row compares the suites on the recordings they all hold at that condition (same names: same scenes, "
           "texts, gaze and seeds); mean CER of the stitched page read by the default offline engine, on-change mode. "
           "RGB: the glasses' RGB snapshot of the same scene (first suite that has one).", "",
           f"![CER against light]({plot.name})", "", "## By light", "", *cer_rows(suites, "lux", "lux", reference), "",
           "## By light and motion", "", *cer_rows(suites, ("lux", "motion"), "lux, motion", reference), ""]
    out.write_text("\n".join(md), encoding="utf-8")
    return out


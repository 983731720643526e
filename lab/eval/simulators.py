"""Two event simulators side by side: the same suite recordings (names, seeds, scenes, gaze, texts)
made by our sensor model and by the second one (hesim-3d), each read end to end, compared by light.

``darkread eval compare-simulators OURS_SUITE OTHER_SUITE`` reads the results each suite's
evaluation stored (``SUITE/eval_runs/<mode>``) and the event rates of the recordings' ``meta.json``,
pairs recordings by name, and writes a Markdown table: a gain that exists only on our own sensor
model shows up as a gap between the two columns.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from darkread.lab.eval.aggregate import group_by, mean, median
from darkread.lab.eval.results import RecordingResult
from darkread.lab.eval.runner import load_results
from darkread.lab.eval.tables import page_as_section, pct

HESIM_NOTE = ("How the second one differs (models/synth/README.md): hesim-3d 0.1.0's H-ESIM with its IMX636 preset "
              "has no photoreceptor low-pass (ours slows in the dark and smears edges), no shot noise on still pixels "
              "(0.018 Hz of dark events instead of our 0.5-3 Hz at 5 lux), one threshold of 0.15 for every pixel (ours "
              "0.18-0.32 with mismatch), noise as a firing probability around the threshold, at most one event per pixel "
              "per 1 ms step stamped at its end; the page's light enters through the camera equation with its dark offset "
              "at the IMX636's 0.08-lux cut-off. The model was trained on our simulator only.")
SIMULATORS_NAME = "simulators.md"  # beside the report: `write_report` puts it in as its "Second simulator" section


@dataclass(frozen=True)
class SimulatorRun:
    """One suite made by one simulator, as evaluated: its results and its recordings' event rates."""

    simulator: str
    results: list[RecordingResult]
    event_rate_hz: dict[str, float]  # recording name -> events per second over the whole sensor

    @classmethod
    def load(cls, suite_dir: str | Path, mode: str) -> SimulatorRun:

        suite = Path(suite_dir)
        work = suite / "eval_runs" / mode
        results = [r for r in load_results(work) if r.scanpath == "model"]
        if not results:
            raise FileNotFoundError(f"{work}: no stored results; run `darkread eval run {suite} --infer {mode}` first")
        metas = {str(r.name): json.loads((suite / str(r.name) / "meta.json").read_text())
                 for r in results if (suite / str(r.name) / "meta.json").is_file()}
        names = {str(m.get("simulator", "darkread")) for m in metas.values()}
        if len(names) != 1:
            raise ValueError(f"{suite}: recordings of several simulators ({', '.join(sorted(names))}); one suite per simulator")
        rates = {name: float(m["event_rate_hz"]) for name, m in metas.items() if "event_rate_hz" in m}
        return cls(names.pop(), results, rates)


def paired_by_name(first: SimulatorRun, second: SimulatorRun) -> list[tuple[RecordingResult, RecordingResult]]:
    """The recordings both suites hold (same name: same spec), in the first suite's order."""
    other = {r.name: r for r in second.results}
    return [(r, other[r.name]) for r in first.results if r.name in other]


def _cells(pairs: Sequence[tuple[RecordingResult, RecordingResult]], first: SimulatorRun, second: SimulatorRun) -> str:
    a = mean(p.rate("darkread") for p, _ in pairs)
    b = mean(q.rate("darkread") for _, q in pairs)
    diff = "–" if a is None or b is None else f"{(b - a) * 100:+.1f} pp"
    rate_a = median(first.event_rate_hz.get(str(p.name)) for p, _ in pairs)
    rate_b = median(second.event_rate_hz.get(str(q.name)) for _, q in pairs)
    return f"{len(pairs)} | {pct(a)} | {pct(b)} | {diff} | {_rate(rate_a)} | {_rate(rate_b)} |"


def _rate(value: float | None) -> str:
    return "–" if value is None else f"{value / 1e3:,.0f} k/s"


def comparison_table(first: SimulatorRun, second: SimulatorRun, key: str | tuple[str, ...] = "lux") -> list[str]:
    """Mean darkread CER per value of ``key`` on both simulators' recordings of the same specs."""
    pairs = paired_by_name(first, second)
    if not pairs:
        return ["No recording name is in both suites."]
    label = " x ".join(key) if isinstance(key, tuple) else key
    a, b = first.simulator, second.simulator
    lines = [f"| {label} | n | CER, `{a}` events | CER, `{b}` events | `{b}` − `{a}` | events/s `{a}` (median) | "
             f"events/s `{b}` (median) |", "|---|---:|---:|---:|---:|---:|---:|"]
    partner = {p.name: q for p, q in pairs}
    for value, group in group_by([p for p, _ in pairs], key).items():
        shown = ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value) if isinstance(value, tuple) else (
            f"{value:g}" if isinstance(value, float) else str(value))
        lines.append(f"| {shown} | " + _cells([(p, partner[p.name]) for p in group], first, second))
    lines.append("| **all** | " + _cells(pairs, first, second))
    return lines


def write_comparison(first_suite: str | Path, second_suite: str | Path, out: str | Path, *, mode: str) -> Path:
    """The Markdown page comparing two simulators' suites (``out``), also returned as its path."""
    first, second = SimulatorRun.load(first_suite, mode), SimulatorRun.load(second_suite, mode)
    md = [
        "# One suite, two event simulators",
        "",
        (f"The same recordings of the suite (`darkread eval make-suite --subset simulator-check`: names, seeds, scenes, "
         f"head motion, gaze and texts alike) made by two event simulators, `{first.simulator}` "
         f"({len(first.results)} recordings) and `{second.simulator}` ({len(second.results)}; `--simulator "
         f"{second.simulator}`), each read end to end by the shipped model in the edge's `{mode}` mode with the "
         "embedded offline OCR; paired by name; CER clipped at 100 % per recording before the mean; events/s over the "
         "whole sensor. Reproduce: `make eval-hesim` (lab/synth/hesim_sensor.py says how the second simulator is "
         "driven)."),
        "",
        *([HESIM_NOTE, ""] if second.simulator == "hesim" else []),
        *comparison_table(first, second, "lux"),
        "",
        *comparison_table(first, second, ("lux", "motion")),
        "",
    ]
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(md))
    return path


def simulator_section(out_dir: str | Path) -> list[str]:
    """The report's "Second simulator" section: the comparison page beside it (``simulators.md``,
    written by ``compare-simulators``), without its title; nothing when there is none."""
    return page_as_section(Path(out_dir) / SIMULATORS_NAME, "Second simulator")

"""Rehearsal windows: what the glasses cut while a simulated reader reads, in the sensor regime the
shipped network was trained on, labelled from the simulator's own pose and ink.

A fine-tune on a new sensor's windows drifts from what the network knew unless every batch also
rehearses the old regime. Random page crops (``synth dataset``) keep the windows' ink F1, but they
are not what the edge cuts while someone reads (fixations, saccades, head motion, deblurred and in
dim light denoised windows): tuned with crops alone, six networks in a row read fresh standard
10-lux pages worse than networks that learned nothing; with these windows in the mix, not
(docs/finetune.md). ``make_rehearsal`` writes one shard directory of them for
``darkread train finetune --synthetic-dir``.

With ``regime="grounded"`` the sessions are the grounded sensor's instead (K over its band, both bias
profiles): not a regime to rehearse but the windows a tune across the band learns from (``lab/train/band.py``).
"""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict
from functools import partial
from pathlib import Path
from typing import Any

from darkread.edge.sources.evk4.bias_profiles import DARK, FACTORY
from darkread.lab.jobs import run_jobs
from darkread.lab.truth import annotate_from_truth
from darkread.models.synth.recording import RecordingSpec, write_recording
from darkread.models.train.annotate import SHARD_NAME
from darkread.models.train.data import count_samples

SUMMARY_NAME = "rehearsal.json"
LUX_LEVELS: tuple[float, ...] = (5.0, 10.0, 10.0, 20.0, 30.0, 50.0)  # the dim end, where forgetting showed
MOTIONS: tuple[str, ...] = ("still", "normal", "walking")
REGIMES: tuple[str, ...] = ("standard", "grounded")
# the grounded sensor's dim end (docs/sensor_model.md), where it differs from the standard one: each lux level
# once at the factory biases and once at the dark profile the glasses switch to below 15 lux
GROUNDED_LUX_LEVELS: tuple[float, ...] = (3.0, 5.0, 7.0, 10.0, 15.0, 30.0)
GROUNDED_BIASES: tuple[str, ...] = (FACTORY, DARK)


def rehearsal_specs(count: int, seed: int, seconds: float = 2.5, regime: str = "standard") -> list[RecordingSpec]:
    """``count`` reading sessions over lux x motion (lux-major), seeds ``seed``, ``seed`` + 1, ...: three lines of
    30 characters of training text, as the tune recordings. ``standard``: the shipped network's own regime.
    ``grounded``: the sensor and head motion of published measurements, each session's photoreceptor K drawn
    over its band (seeded), at both bias profiles (lux x motion x biases)."""
    if count < 1:
        raise ValueError(f"--recordings {count}: must be at least 1")
    if regime not in REGIMES:
        raise ValueError(f"--regime {regime}: use one of {', '.join(REGIMES)}")
    if regime == "standard":
        grid = [(lux, motion, FACTORY) for lux in LUX_LEVELS for motion in MOTIONS]
        extra: dict[str, Any] = {"regime": "standard"}
    else:
        grid = [(lux, motion, biases) for lux in GROUNDED_LUX_LEVELS for motion in MOTIONS for biases in GROUNDED_BIASES]
        extra = {"regime": "grounded", "motion_regime": "grounded"}
    return [RecordingSpec(lux=grid[i % len(grid)][0], motion=grid[i % len(grid)][1], kind="paragraph", seconds=seconds,
                          seed=seed + i, n_lines=3, line_chars=30, split="train", bias_profile=grid[i % len(grid)][2],
                          **extra)
            for i in range(count)]


def _one(indexed: tuple[int, RecordingSpec], work: Path, out: Path, every_ms: float) -> dict[str, Any]:
    """Simulate session ``index`` (``indexed``: index and spec), label its windows from the truth,
    keep only the shard (a process task)."""
    index, spec = indexed

    recording, labelled = work / f"s{spec.seed}", work / f"s{spec.seed}_windows"
    write_recording(recording, spec, progress=False)
    summary = annotate_from_truth(recording, labelled, every_ms=every_ms)
    (labelled / SHARD_NAME).replace(out / f"shard-{index:05d}.npz")
    shutil.rmtree(recording)
    shutil.rmtree(labelled)
    return {**{k: summary[k] for k in ("lux", "motion", "windows", "ink_share")}, "seed": spec.seed, "biases": spec.bias_profile}


def make_rehearsal(out: str | Path, count: int = 18, seed: int = 601, every_ms: float = 10.0, seconds: float = 2.5,
                   jobs: int = 1, progress: bool = True, regime: str = "standard") -> dict[str, Any]:
    """Write OUT/shard-NNNNN.npz (one per session, in seed order) and OUT/rehearsal.json; a shard
    already there is kept, so an interrupted run resumes."""
    from tqdm import tqdm


    if every_ms <= 0:
        raise ValueError(f"--every-ms {every_ms}: must be positive")
    out = Path(out)
    specs = rehearsal_specs(count, seed, seconds, regime)
    previous = _previous(out)
    settings = {"count": count, "first_seed": seed, "every_ms": every_ms,
                "spec": {k: v for k, v in asdict(specs[0]).items() if k not in ("lux", "motion", "seed", "bias_profile")}}
    settings = json.loads(json.dumps(settings))  # as rehearsal.json reads back (tuples as lists)
    if previous and any(previous.get(k) != v for k, v in settings.items()):
        raise ValueError(f"{out} holds rehearsal windows made with other settings ({previous.get('count')} sessions from seed "
                         f"{previous.get('first_seed')}, every {previous.get('every_ms')} ms); give another output directory")
    out.mkdir(parents=True, exist_ok=True)
    if not previous:  # written first, so a resumed run can tell whose shards these are
        (out / SUMMARY_NAME).write_text(json.dumps({**settings, "sessions": []}, indent=1) + "\n", encoding="utf-8")
    work = out / ".work"
    work.mkdir(exist_ok=True)
    todo = [(i, s) for i, s in enumerate(specs) if not (out / f"shard-{i:05d}.npz").is_file()]
    bar = tqdm(total=len(specs), initial=len(specs) - len(todo), desc="reading sessions", unit="session", disable=not progress)
    task = partial(_one, work=work, out=out, every_ms=every_ms)
    done = dict(zip([i for i, _ in todo], run_jobs(task, todo, jobs, bar.update), strict=True))
    bar.close()
    shutil.rmtree(work, ignore_errors=True)
    before = dict(enumerate(previous.get("sessions", [])))
    sessions = [done.get(i) or before.get(i) or _found(out / f"shard-{i:05d}.npz", spec) for i, spec in enumerate(specs)]
    summary = {"sessions": sessions, "windows": sum(s.get("windows", 0) for s in sessions), **settings}
    (out / SUMMARY_NAME).write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return summary


def _found(shard: Path, spec: RecordingSpec) -> dict[str, Any]:
    """A session an interrupted run finished but did not get to record: counted from its shard."""

    return {"lux": spec.lux, "motion": spec.motion, "windows": count_samples(shard), "seed": spec.seed, "biases": spec.bias_profile}


def _previous(out: Path) -> dict[str, Any]:
    """What a previous run into ``out`` recorded (empty when there is none or it is unreadable)."""
    try:
        found = json.loads((out / SUMMARY_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return found if isinstance(found, dict) else {}


def describe(summary: dict[str, Any]) -> str:
    """Sessions and windows per lux level, on one line."""
    rows: dict[float, list[int]] = {}
    for s in summary["sessions"]:
        rows.setdefault(float(s["lux"]), []).append(int(s.get("windows", 0)))
    parts = [f"{lux:g} lux: {len(w)} sessions, {sum(w)} windows" for lux, w in sorted(rows.items())]
    return f"{summary['windows']} windows from {len(summary['sessions'])} reading sessions (" + "; ".join(parts) + ")"

"""Synthetic-data throughput: training samples per second and recording seconds per wall second.

* ``synth_samples_per_s``: one process making training samples (page render, window simulation
  at >= 2 kHz until 1600 events, voxel grid, ink mask), mixed lux / motion / text. The goal for the
  dataset is 90 000 samples in under 2 h with 2 workers, i.e. >= 6.25 samples/s per process. The
  reference measured in the same run is the render-only cost (page + warps, no sensor), which
  bounds what a faster sensor model could gain.
* ``synth_sim_s_per_wall_s``: a whole recording (normal motion, 100 lux, 3 lines) simulated over
  the region the fovea can reach plus background noise, encoded to EVT3; compared with real time.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from darkread.lab.bench import BenchContext, Figure
from darkread.models.synth.recording import RecordingSpec, write_recording
from darkread.models.synth.scene import Region
from darkread.models.synth.session import SessionSpec, make_session
from darkread.models.synth.shards import FOVEA, SAMPLES_PER_PAGE, make_samples


def samples_per_s(n_pages: int, seed: int = 100, per_page: int = SAMPLES_PER_PAGE) -> float:
    start = time.perf_counter()
    n = 0
    for page in range(n_pages):
        v, _, _ = make_samples(SessionSpec(duration_s=4.0), seed + page, per_page)
        n += v.shape[0]
    return n / (time.perf_counter() - start)


def render_only_samples_per_s(
    n_pages: int, steps_per_sample: int = 40, seed: int = 100, per_page: int = SAMPLES_PER_PAGE
) -> float:
    start = time.perf_counter()
    n = 0
    rng = np.random.default_rng(seed)
    for page in range(n_pages):
        session = make_session(SessionSpec(duration_s=4.0), seed + page)
        for _ in range(per_page):
            x0, y0 = int(rng.integers(0, 1080)), int(rng.integers(0, 620))
            region = Region.of(session.calib, x0, y0, FOVEA.width, FOVEA.height)
            t = float(rng.uniform(0.3, 3.0))
            for k in range(steps_per_sample):
                session.scene.irradiance(region, t + k * 5e-4)
            n += 1
    return n / (time.perf_counter() - start)


def sim_seconds_per_wall_s(seconds: float) -> float:
    spec = RecordingSpec(lux=100.0, motion="normal", kind="paragraph", seconds=seconds, seed=7, xheight_px=10.0,
                         n_lines=3, line_chars=30)
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        write_recording(Path(tmp) / "rec", spec, progress=False)
        return seconds / (time.perf_counter() - start)


def run(ctx: BenchContext) -> list[Figure]:
    pages = ctx.runs(4, 1)
    per_page = ctx.runs(SAMPLES_PER_PAGE, SAMPLES_PER_PAGE, 1)
    sps = samples_per_s(pages, per_page=per_page)
    render = render_only_samples_per_s(pages, per_page=per_page)
    sim = sim_seconds_per_wall_s(1.0 if not (ctx.quick or ctx.smoke) else 0.1 if ctx.smoke else 0.3)
    return [
        Figure(
            key="synth_samples_per_s",
            value=round(sps, 2),
            label="training samples per second, one process",
            reference=f"render only (no sensor): {render:.1f} samples/s",
            goal=">= 6.25 per process (90k in 2 h with 2 workers)",
        ),
        Figure(
            key="synth_sim_s_per_wall_s",
            value=round(sim, 3),
            label="recording: simulated seconds per wall second (normal motion, 100 lux)",
            reference="real time: 1.0",
            goal="informational",
        ),
    ]

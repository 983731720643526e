"""Training samples and shards: voxel grid of the last 1600 foveated events + ideal ink mask.

Only the 100 x 200 window the fovea keeps is simulated (its pixels' events are all the voxel grid
sees), so a sample costs a few dozen sensor steps. The window follows a noisy gaze estimate of a
reading scanpath; tracker bias and noise put some windows partly off the text.
"""

from __future__ import annotations

import json
import logging
import math
import multiprocessing as mp
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from darkread.core.mask_bits import pack_rows
from darkread.edge.config import PipelineConfig
from darkread.edge.fovea import FoveaConfig, window_origin
from darkread.edge.sources.evk4.bias_profiles import FACTORY, profile_offsets
from darkread.edge.voxel import VoxelConfig, voxel_grid
from darkread.models.synth.camera import SENSOR_WH, pixels_per_degree
from darkread.models.synth.fonts import HELD_OUT_FAMILIES, TRAIN_FAMILIES, families_of, font_split
from darkread.models.synth.motion import MOTION_REGIMES
from darkread.models.synth.scene import Region, Scene
from darkread.models.synth.sensor import EventSensor, SensorParams, concat_events
from darkread.models.synth.sensor_profile import profile_at
from darkread.models.synth.session import LUX_RANGE, Session, SessionSpec, choose_dt_us, make_session, random_lux

log = logging.getLogger(__name__)

FOVEA = FoveaConfig()
VOXEL = VoxelConfig()
N_EVENTS = PipelineConfig().n_events  # events per voxel grid, as the edge bins them
SAMPLES_PER_PAGE = 8
SHARD_SIZE = 250
MAX_WINDOW_S = 0.5  # give up collecting events after this much simulated time
SHARD_FORMAT_VERSION = 1
# When a training target is drawn. "end": the ink at the window's newest event. "evidence": the
# ink at the time its events show best; in the dark the photoreceptor lags and a window spans more
# time, so the events trail the page by 10-30 ms and a target at the newest event teaches a blur.
TARGET_TIMES: tuple[str, ...] = ("end", "evidence")
EVIDENCE_LAGS_MS = np.arange(0.0, 60.1, 2.5)  # the lags searched for the evidence time


# Per-sample arrays of a shard besides voxels and targets (what ``write_shard`` writes).
METADATA_KEYS: tuple[str, ...] = ("lux", "xheight_px", "motion", "font", "kind", "seed", "window_origin", "t_end_us", "n_events",
                                  "target_lag_us")


@dataclass
class SampleMeta:
    lux: float
    motion: str
    kind: str
    font: str
    xheight_px: float
    seed: int
    x0: int
    y0: int
    t_end_us: int
    n_events: int
    target_lag_us: int = 0  # the target shows the ink this long before t_end (0: at t_end)


def simulate_window(
    scene: Scene,
    params: SensorParams,
    region: Region,
    t_start_s: float,
    rng: np.random.Generator,
    *,
    n_events: int = N_EVENTS,
    max_s: float = MAX_WINDOW_S,
) -> tuple[np.ndarray, float]:
    """Events of ``region`` from ``t_start_s`` until ``n_events`` have fired; returns (events, t_end_s).

    The photoreceptor filter is warmed up for ~30 ms first and the references start in their
    steady state, so there is no start-up transient.
    """
    dt_us = choose_dt_us(scene)
    sensor = EventSensor(params, (region.height, region.width), (region.x0, region.y0), rng)
    warm_steps, warm_dt_us = 15, 2000.0
    t = t_start_s - warm_steps * warm_dt_us * 1e-6
    sensor.reset(scene.irradiance(region, t), t * 1e6)
    for _ in range(warm_steps):
        t += warm_dt_us * 1e-6
        sensor.settle(scene.irradiance(region, t), warm_dt_us)
    sensor.rebase()
    chunks, count = [], 0
    t_stop = t_start_s + max_s
    while count < n_events and t < t_stop:
        t += dt_us * 1e-6
        ev = sensor.step(scene.irradiance(region, t), dt_us)
        if ev.size:
            chunks.append(ev)
            count += ev.size
    events = concat_events(chunks)
    return events, t


def window_count_image(window_events: np.ndarray, origin: tuple[int, int], hw: tuple[int, int] = (FOVEA.height, FOVEA.width)) -> np.ndarray:
    """Events per pixel of the window at ``origin``, both polarities, lightly blurred (float32 ``hw``):
    what a window's events show of the page, for matching it against the ink's edges (here and in
    ``train.annotate``)."""
    x = window_events["x"].astype(np.int64) - origin[0]
    y = window_events["y"].astype(np.int64) - origin[1]
    counts = np.bincount(y * hw[1] + x, minlength=hw[0] * hw[1]).astype(np.float32).reshape(hw)
    return cv2.GaussianBlur(counts, (0, 0), 1.0)


def ncc(a: np.ndarray, b: np.ndarray) -> float:
    """Normalised cross-correlation of two images of one shape (0 when either is flat)."""
    a = a - a.mean()
    b = b - b.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 0 else 0.0


def ink_edges(mask: np.ndarray) -> np.ndarray:
    """Where a moving print makes events: the ink mask's outline, lightly blurred (float32)."""
    edge = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8))
    return cv2.GaussianBlur(edge.astype(np.float32), (0, 0), 1.0)


def best_lag(evidence: np.ndarray, edge_maps: np.ndarray) -> int:
    """Index of the edge map [k, h, w] that correlates best with the event image (0 on a tie or a
    flat window: no evidence of a lag is no lag)."""
    score = np.array([ncc(edge, evidence) for edge in edge_maps])
    if np.ptp(score) < 1e-3:
        return 0
    return int(np.argmax(score))


def evidence_target(scene: Scene, region: Region, events: np.ndarray, t_end: float) -> tuple[np.ndarray, float]:
    """(ink mask, lag s): the window's ink at the time its events match best, searched over
    ``EVIDENCE_LAGS_MS`` before ``t_end``."""
    masks = [scene.ink_mask(region, t_end - lag * 1e-3) for lag in EVIDENCE_LAGS_MS]
    evidence = window_count_image(events, (region.x0, region.y0), masks[0].shape)
    k = best_lag(evidence, np.stack([ink_edges(m) for m in masks]))
    return masks[k], float(EVIDENCE_LAGS_MS[k]) * 1e-3


def gaze_window_origin(session: Session, scene: Scene, t_s: float, rng: np.random.Generator) -> tuple[int, int]:
    """Window origin from a noisy, late gaze estimate (tracker bias + noise, sometimes far off)."""
    tr = session.tracker
    true_tex = session.scanpath.position(t_s - tr.latency_us * 1e-6)
    uv = scene.project(true_tex[None, :], t_s)[0]
    ppd = pixels_per_degree(scene.calib)
    err_deg = np.degrees(np.asarray(tr.bias_rad)) + rng.normal(0.0, math.degrees(tr.fast_sd_rad + tr.slow_sd_rad), 2)
    uv = uv + err_deg * ppd * np.array([-1.0, -1.0])  # CPF yaw/pitch errors flip into image x/y
    if rng.random() < 0.1:  # some windows largely off the text
        uv = uv + rng.uniform(-1, 1, 2) * np.array([FOVEA.width, FOVEA.height])
    if not np.all(np.isfinite(uv)):
        uv = np.array([SENSOR_WH[0] / 2, SENSOR_WH[1] / 2])
    uv = np.clip(uv, 0, np.array(SENSOR_WH) - 1)
    return window_origin((float(uv[0]), float(uv[1])), SENSOR_WH, FOVEA)


def make_samples(
    spec: SessionSpec, seed: int, n: int, *, lux: float | None = None, lux_range: tuple[float, float] = LUX_RANGE,
    target_time: str = "end",
) -> tuple[np.ndarray, np.ndarray, list[SampleMeta]]:
    """``n`` samples from one page session: voxels float16 [n,4,100,200], targets uint8 [n,100,200];
    each sample's light is ``lux``, else the spec's, else log-uniform over ``lux_range``; each
    target is the ink at ``target_time`` (``TARGET_TIMES``). The windows and voxels do not depend on it."""
    if target_time not in TARGET_TIMES:
        raise ValueError(f"unknown target time {target_time!r}; use one of {', '.join(TARGET_TIMES)}")
    session = make_session(spec, seed)
    rng = np.random.default_rng([seed, 1])
    voxels = np.zeros((n, VOXEL.bins, VOXEL.height, VOXEL.width), dtype=np.float16)
    targets = np.zeros((n, FOVEA.height, FOVEA.width), dtype=np.uint8)
    metas = []
    duration = session.scanpath.t[-1]
    for i in range(n):
        sample_lux = lux if lux is not None else (spec.lux if spec.lux is not None else random_lux(rng, *lux_range))
        scene, params = session.with_lux(sample_lux, rng)
        t_s = float(rng.uniform(0.3, max(0.31, duration - MAX_WINDOW_S)))
        x0, y0 = gaze_window_origin(session, scene, t_s, rng)
        region = Region.of(scene.calib, x0, y0, FOVEA.width, FOVEA.height)
        events, t_end = simulate_window(scene, params, region, t_s, rng)
        window = events[-N_EVENTS:]
        voxels[i] = voxel_grid(window, x0, y0, VOXEL).astype(np.float16)  # region events: all inside
        if target_time == "evidence":
            targets[i], lag_s = evidence_target(scene, region, window, t_end)
        else:
            targets[i], lag_s = scene.ink_mask(region, t_end), 0.0
        metas.append(
            SampleMeta(
                lux=float(sample_lux),
                motion=scene.motion.level,
                kind=session.kind,
                font=session.page.font,
                xheight_px=round(scene.xheight_px(t_end), 3),
                seed=int(seed),
                x0=int(x0),
                y0=int(y0),
                t_end_us=int(round(t_end * 1e6)),
                n_events=int(events.size),
                target_lag_us=int(round(lag_s * 1e6)),
            )
        )
    return voxels, targets, metas


def write_shard(path: Path, voxels: np.ndarray, targets: np.ndarray, metas: list[SampleMeta],
                ignore: np.ndarray | None = None) -> None:
    """``ignore`` (uint8 [n,H,W], 1 = not a training pixel, e.g. an annotated window's markers) is
    stored as packed bits under ``ignore`` only when given: a shard without it has every pixel valid."""
    cols = {k: [getattr(m, k) for m in metas] for k in SampleMeta.__dataclass_fields__}
    extra = {} if ignore is None else {"ignore": pack_rows(np.asarray(ignore, np.uint8))}
    np.savez_compressed(
        path,
        **extra,  # type: ignore[arg-type]  # numpy's stub lets **arrays reach allow_pickle: bool; these are array names
        voxels=voxels.astype(np.float16),
        targets=pack_rows(targets),
        target_shape=np.array(targets.shape[1:], dtype=np.int32),
        lux=np.array(cols["lux"], dtype=np.float32),
        xheight_px=np.array(cols["xheight_px"], dtype=np.float32),
        motion=np.array(cols["motion"], dtype=str),
        font=np.array(cols["font"], dtype=str),
        kind=np.array(cols["kind"], dtype=str),
        seed=np.array(cols["seed"], dtype=np.int64),
        window_origin=np.array([[m.x0, m.y0] for m in metas], dtype=np.int32).reshape(-1, 2),
        t_end_us=np.array(cols["t_end_us"], dtype=np.int64),
        n_events=np.array(cols["n_events"], dtype=np.int32),
        target_lag_us=np.array(cols["target_lag_us"], dtype=np.int64),
    )


def shard_seed(base_seed: int, split: str, held_out: bool, shard_index: int, page_index: int) -> int:
    """A page's seed: a pure function of the dataset seed and the page's place (worker-independent)."""
    ss = np.random.SeedSequence([int(base_seed), {"train": 0, "val": 1}.get(split, 2), int(held_out), shard_index, page_index])
    return int(ss.generate_state(1, dtype=np.uint32)[0])


@dataclass(frozen=True)
class ShardTask:
    """One shard of a dataset (a worker's task): where, which, how many, and how its pages are drawn."""

    out_dir: Path
    index: int
    count: int
    base_seed: int
    split: str
    held_out: bool
    lux_range: tuple[float, float]
    target_time: str
    more_fonts: bool
    regime: str
    sensor_profile: str | None
    biases: tuple[str, ...] = (FACTORY,)  # each page's IMX636 bias profile, drawn from these by its seed
    motion_regime: str = "standard"  # the head motion's draws (motion.MOTION_REGIMES)

    @property
    def path(self) -> Path:
        return Path(self.out_dir) / f"shard-{self.index:05d}.npz"


def page_biases(biases: tuple[str, ...], page_seed: int) -> str:
    """The bias profile of the page with this seed: one of ``biases``, a pure function of the seed."""
    return biases[page_seed % len(biases)]


def build_shard(task: ShardTask) -> dict:
    """Make one shard (a multiprocessing task)."""
    t0 = time.perf_counter()
    spec = SessionSpec(split=task.split, held_out=task.held_out, duration_s=4.0, more_fonts=task.more_fonts,
                       regime=task.regime, sensor_profile=task.sensor_profile, motion_regime=task.motion_regime)
    parts_v: list[np.ndarray] = []
    parts_t: list[np.ndarray] = []
    metas: list[SampleMeta] = []
    page = 0
    while len(metas) < task.count:
        k = min(SAMPLES_PER_PAGE, task.count - len(metas))
        seed = shard_seed(task.base_seed, task.split, task.held_out, task.index, page)
        v, t, m = make_samples(replace(spec, bias_profile=page_biases(task.biases, seed)), seed, k,
                               lux_range=task.lux_range, target_time=task.target_time)
        parts_v.append(v)
        parts_t.append(t)
        metas.extend(m)
        page += 1
    tmp = task.path.with_suffix(".tmp.npz")
    write_shard(tmp, np.concatenate(parts_v), np.concatenate(parts_t), metas)
    tmp.replace(task.path)
    return {"index": task.index, "count": len(metas), "seconds": time.perf_counter() - t0, "path": task.path.name}


def category_counts(out_dir: str | Path, shard_names: list[str]) -> dict[str, dict[str, int]]:
    """How many samples per font, motion level, text kind and lux band (read from the shards)."""
    counts: dict[str, dict[str, int]] = {"font": {}, "motion": {}, "kind": {}, "lux": {}}
    bands = np.array([0, 10, 30, 100, 300, 1e9])
    labels = ["<10", "10-30", "30-100", "100-300", ">=300"]
    for name in shard_names:
        path = Path(out_dir) / name
        if not path.is_file():
            continue
        with np.load(path, allow_pickle=False) as z:
            for key in ("font", "motion", "kind"):
                values, n = np.unique(z[key], return_counts=True)
                for v, c in zip(values, n, strict=True):
                    counts[key][str(v)] = counts[key].get(str(v), 0) + int(c)
            idx = np.digitize(z["lux"], bands) - 1
            for i, label in enumerate(labels):
                counts["lux"][label] = counts["lux"].get(label, 0) + int((idx == i).sum())
    return counts


def build_dataset(
    out_dir: str | Path,
    samples: int,
    *,
    workers: int = 2,
    seed: int = 0,
    split: str = "train",
    held_out: bool = False,
    shard_size: int = SHARD_SIZE,
    progress: bool = True,
    lux_range: tuple[float, float] = LUX_RANGE,
    target_time: str = "end",
    more_fonts: bool = False,
    regime: str = "standard",
    sensor_profile: str | None = None,
    biases: tuple[str, ...] = (FACTORY,),
    motion_regime: str = "standard",
) -> dict:
    """Write ``samples`` samples as shards plus ``dataset.json``; deterministic for ``seed`` (any worker count).
    ``lux_range``: the light, log-uniform between the two (a low-light set for the dark end, say 4..40);
    ``target_time``: when each target shows the page (``TARGET_TIMES``); ``more_fonts``: a training set
    drawn from ``MORE_TRAIN_FAMILIES`` too; ``regime``: the sensor's (``sensor.REGIMES``); ``sensor_profile``:
    with the grounded regime, the sensor drawn around a measured profile (``sensor_profile.py``); ``biases``: the
    IMX636 bias profiles pages are made under (grounded; each page one of them, by its seed: a network for
    both profiles the glasses switch between); ``motion_regime``: the head motion's draws."""
    if target_time not in TARGET_TIMES:
        raise ValueError(f"--target-time {target_time!r}: use one of {', '.join(TARGET_TIMES)}")
    if samples < 1:
        raise ValueError("--samples must be at least 1")
    lo, hi = (float(v) for v in lux_range)
    if not (0 < lo <= hi):
        raise ValueError(f"--lux {lo:g} {hi:g}: give two light levels, 0 < LOW <= HIGH")
    if split not in ("train", "val"):
        raise ValueError(f"unknown split {split!r}; use 'train' or 'val'")
    if more_fonts and (split != "train" or held_out):
        raise ValueError("--more-fonts is for training sets: not with --split val or --held-out")
    if sensor_profile is not None:
        if regime != "grounded":
            raise ValueError(f"--sensor-profile is drawn from by the grounded regime: add --regime grounded (not {regime})")
        sensor_profile = str(Path(sensor_profile).resolve())
        profile_at(sensor_profile)  # missing or wrong: one line before any work
    biases = tuple(biases)
    if not biases:
        raise ValueError("--biases: name at least one bias profile")
    for name in biases:
        profile_offsets(name)  # an unknown profile: one line before any work
    if biases != (FACTORY,) and regime != "grounded":
        raise ValueError(f"--biases {' '.join(biases)}: biases are modelled in the grounded regime only (add --regime grounded)")
    if motion_regime not in MOTION_REGIMES:
        raise ValueError(f"--motion-regime {motion_regime!r}: use one of {', '.join(MOTION_REGIMES)}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    n_shards = math.ceil(samples / shard_size)
    tasks = [
        ShardTask(out, i, min(shard_size, samples - i * shard_size), int(seed), split, bool(held_out), (lo, hi), target_time,
                  bool(more_fonts), regime, sensor_profile, biases, motion_regime)
        for i in range(n_shards)
    ]
    todo = [t for t in tasks if not t.path.exists()]
    t0 = time.perf_counter()
    from tqdm import tqdm

    bar = tqdm(total=samples, initial=samples - sum(t.count for t in todo), unit="sample", disable=not progress)
    results = []
    if workers <= 1:
        for task in todo:
            results.append(build_shard(task))
            bar.update(results[-1]["count"])
    else:

        with mp.get_context("spawn").Pool(workers) as pool:
            for res in pool.imap_unordered(build_shard, todo):
                results.append(res)
                bar.update(res["count"])
    bar.close()
    elapsed = time.perf_counter() - t0
    fonts_of_the_set = {
        "train_families": list(TRAIN_FAMILIES),
        "held_out_families": list(HELD_OUT_FAMILIES),
        "families_in_this_set": list(families_of(font_split(split, held_out, more_fonts))),
    }
    manifest = {
        "format_version": SHARD_FORMAT_VERSION,
        "samples": samples,
        "shards": [f"shard-{i:05d}.npz" for i in range(n_shards)],
        "shard_size": shard_size,
        "seed": int(seed),
        "split": split,
        "held_out": bool(held_out),
        "fonts": fonts_of_the_set,
        "text_split": "val" if split == "val" else "train",
        "voxel": {"bins": VOXEL.bins, "n_events": N_EVENTS, "height": VOXEL.height, "width": VOXEL.width,
                  "normalize": VOXEL.normalize},
        "fovea": asdict(FOVEA),
        "target": "uint8 1 = ink, 0 = paper; ideal ink mask warped into the window at "
                  + ("t_end" if target_time == "end" else "t_end - target_lag_us, the lag its events match best")
                  + "; np.packbits on axis -1",
        "target_time": target_time,
        "parameters": {
            "lux": f"log-uniform {lo:g}..{hi:g}",
            "motion": {"still": 0.3, "normal": 0.5, "walking": 0.2},
            "text_kind": {"letters": 0.15, "words": 0.3, "pangram": 0.15, "paragraph": 0.4},
            "xheight_px": "uniform 5..16 (nominal)",
            "samples_per_page": SAMPLES_PER_PAGE,
            "sensor": ("see darkread.models.synth.sensor.random_sensor_params" if regime == "standard"
                       else f"regime {regime} (darkread.models.synth.sensor.regime_sensor_params)"),
            "sensor_profile": sensor_profile,
            "biases": list(biases),
            "motion_regime": motion_regime,
        },
        "counts": category_counts(out, [f"shard-{i:05d}.npz" for i in range(n_shards)]),
        "generation_seconds": round(elapsed, 1),
        "samples_per_s": round(sum(r["count"] for r in results) / max(elapsed, 1e-9), 2),
    }
    (out / "dataset.json").write_text(json.dumps(manifest, indent=2))
    return manifest

"""How long the network takes a window on one core: the model card's latency and the benchmark's.

Lives with training because ``darkread train all`` writes the figures into the model card; the lab's
benchmark (``darkread.lab.bench.inference``) calls the same functions.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from darkread.edge.reconstruct import Reconstructor


def best_median_s(call: Callable[[], object], runs: int, repeats: int = 3, warmup: int = 5) -> float:
    """Best of ``repeats`` medians of ``runs`` timed calls, in seconds.

    The host may be shared: the best median is the figure that repeats from run to run.
    """
    for _ in range(warmup):
        call()
    best = float("inf")
    for _ in range(repeats):
        times = np.empty(runs)
        for i in range(runs):
            start = time.perf_counter()
            call()
            times[i] = time.perf_counter() - start
        best = min(best, float(np.median(times)))
    return best


def example_voxel(seed: int = 0) -> np.ndarray:
    """A sparse voxel grid like a 1600-event window (about 8 % of the pixels carry events)."""
    rng = np.random.default_rng(seed)
    shape = (4, 100, 200)
    return (rng.normal(size=shape) * (rng.random(shape) < 0.08)).astype(np.float32)


def median_ms(call: Callable[[], object], runs: int, repeats: int = 3, warmup: int = 5) -> float:
    return best_median_s(call, runs, repeats, warmup) * 1e3


def onnx_latency_ms(model_path: str | Path, runs: int = 60, repeats: int = 3) -> float:
    rec = Reconstructor(model_path, threads=1, warmup=3)
    voxel = example_voxel()
    return median_ms(lambda: rec.logits(voxel), runs, repeats)


def reference_latency_ms(runs: int) -> tuple[float, str]:
    """The reference latency (ms) and what it measured: torch eager when installed, else the naive baseline."""
    voxel = example_voxel()
    try:
        import torch

        from darkread.models.train.net import BinaryUNet  # optional: torch is the reference where installed
    except ImportError:
        from darkread.models.train.baseline import BaselineParams, predict  # optional: torch is the reference where installed

        ms = median_ms(lambda: predict(voxel, BaselineParams()), runs)
        return ms, f"naive count-image baseline: {ms:.2f} ms"
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        model = BinaryUNet().eval()
        x = torch.from_numpy(voxel[None])
        with torch.inference_mode():
            ms = median_ms(lambda: model(x), max(10, runs // 3))
    finally:
        torch.set_num_threads(threads)
    return ms, f"same net, torch eager 1 thread: {ms:.2f} ms"

"""Reconstruction latency per 100x200 window on one core: the shipped ONNX U-Net, fp32 and static int8.

Reference measured in the same run: the same network in PyTorch eager mode on one thread when
torch is installed (the training stack), else the naive count-image baseline (numpy + OpenCV);
and the previous network (``binary_unet_previous.onnx``: 53 k parameters, a 64-wide 1/8 scale with four
blocks where the shipped one has 96 and eight), alternated with the shipped one:
``inference_cost_ratio_vs_previous`` (issue 20's budget: at most 1.5).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from darkread.bench import BenchContext, Figure, best_median_s

INT8_FILENAME = "binary_unet_int8.onnx"
PREVIOUS_FILENAME = "binary_unet_previous.onnx"  # the network shipped before (53 k parameters, 1/8 scale 64 wide, 4 blocks)


def example_voxel(seed: int = 0) -> np.ndarray:
    """A sparse voxel grid like a 1600-event window (about 8 % of the pixels carry events)."""
    rng = np.random.default_rng(seed)
    shape = (4, 100, 200)
    return (rng.normal(size=shape) * (rng.random(shape) < 0.08)).astype(np.float32)


def median_ms(call: Callable[[], object], runs: int, repeats: int = 3, warmup: int = 5) -> float:
    return best_median_s(call, runs, repeats, warmup) * 1e3


def onnx_latency_ms(model_path: str | Path, runs: int = 60, repeats: int = 3) -> float:
    from darkread.edge.reconstruct import Reconstructor

    rec = Reconstructor(model_path, threads=1, warmup=3)
    voxel = example_voxel()
    return median_ms(lambda: rec.logits(voxel), runs, repeats)


def reference_latency_ms(runs: int) -> tuple[float, str]:
    """The reference latency (ms) and what it measured: torch eager when installed, else the naive baseline."""
    voxel = example_voxel()
    try:
        import torch

        from darkread.models.train.net import BinaryUNet
    except ImportError:
        from darkread.models.train.baseline import BaselineParams, predict

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


def run(ctx: BenchContext) -> list[Figure]:
    from darkread.edge.reconstruct import default_model_path

    fp32 = default_model_path()
    if not fp32.is_file():
        ctx.notes.append(f"inference: no shipped model at {fp32}; run `darkread train all`")
        return []
    runs = ctx.runs(100, 20, 3)
    reference_ms, reference = reference_latency_ms(runs)
    figures = [
        Figure("inference_ms_fp32", onnx_latency_ms(fp32, runs), "U-Net fp32 ORT, 1 core (ms/window)", reference, "<= 3 ms (goal 2)"),
    ]
    int8 = fp32.with_name(INT8_FILENAME)
    if int8.is_file():
        figures.append(
            Figure("inference_ms_int8", onnx_latency_ms(int8, runs), "U-Net int8 QDQ ORT, 1 core (ms/window)", reference, "<= 3 ms")
        )
    else:
        ctx.notes.append(f"inference: no int8 model at {int8}")
    figures.append(Figure("inference_ms_reference", reference_ms, "reference (see column), 1 core (ms/window)", reference))
    previous = fp32.with_name(PREVIOUS_FILENAME)
    if previous.is_file():
        # alternated, so a drift of the host's speed falls on both alike
        shipped_ms, previous_ms = [], []
        for _ in range(3):
            shipped_ms.append(onnx_latency_ms(fp32, runs, repeats=1))
            previous_ms.append(onnx_latency_ms(previous, runs, repeats=1))
        ratio = min(shipped_ms) / min(previous_ms)
        figures += [
            Figure("inference_ms_previous_model", min(previous_ms), "the previous network (53 k parameters), fp32 ORT, 1 core (ms/window)",
                   f"shipped network, same run, alternated: {min(shipped_ms):.2f} ms"),
            Figure("inference_cost_ratio_vs_previous", ratio, "per-window inference cost, shipped / previous network (same run)",
                   f"{min(shipped_ms):.2f} / {min(previous_ms):.2f} ms", "<= 1.5"),
        ]
    else:
        ctx.notes.append(f"inference: no previous network at {previous}")
    return figures

"""Reconstruction latency per 100x200 window on one core: the shipped ONNX U-Net, fp32 and static int8.

Reference measured in the same run: the same network in PyTorch eager mode on one thread when
torch is installed (the training stack), else the naive count-image baseline (numpy + OpenCV);
and the previous network (``binary_unet_previous.onnx``: 53 k parameters, a 64-wide 1/8 scale with four
blocks where the shipped one has 96 and eight), alternated with the shipped one:
``inference_cost_ratio_vs_previous`` (issue 20's budget: at most 1.5); and the network tuned across the
sensor's band (``lab/networks/binary_unet_band.onnx``, issue 48's budget: at most 1.5x the shipped one's
cost), alternated the same way: ``inference_cost_ratio_band_vs_shipped``.
"""

from __future__ import annotations

from pathlib import Path

from darkread.edge.reconstruct import default_model_path
from darkread.lab import BAND_NETWORK, PREVIOUS_NETWORK
from darkread.lab.bench import BenchContext, Figure
from darkread.models.train.latency import onnx_latency_ms, reference_latency_ms

INT8_FILENAME = "binary_unet_int8.onnx"


def run(ctx: BenchContext) -> list[Figure]:

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
    previous = PREVIOUS_NETWORK
    if previous.is_file():
        shipped_ms, previous_ms = alternated_ms(fp32, previous, runs)
        figures += [
            Figure("inference_ms_previous_model", previous_ms, "the previous network (53 k parameters), fp32 ORT, 1 core (ms/window)",
                   f"shipped network, same run, alternated: {shipped_ms:.2f} ms"),
            Figure("inference_cost_ratio_vs_previous", shipped_ms / previous_ms, "per-window inference cost, shipped / previous network (same run)",
                   f"{shipped_ms:.2f} / {previous_ms:.2f} ms", "<= 1.5"),
        ]
    else:
        ctx.notes.append(f"inference: no previous network at {previous}")
    if BAND_NETWORK.is_file():
        shipped_ms, band_ms = alternated_ms(fp32, BAND_NETWORK, runs)
        figures.append(Figure("inference_cost_ratio_band_vs_shipped", band_ms / shipped_ms,
                              "per-window inference cost, network tuned across the band / shipped (same run)",
                              f"{band_ms:.2f} / {shipped_ms:.2f} ms", "<= 1.5"))
    return figures


def alternated_ms(first: Path, second: Path, runs: int, rounds: int = 3) -> tuple[float, float]:
    """The best ms per window of two networks timed in turn, so a drift of the host's speed falls on both alike."""
    times: tuple[list[float], list[float]] = ([], [])
    for _ in range(rounds):
        for model, out in zip((first, second), times, strict=True):
            out.append(onnx_latency_ms(model, runs, repeats=1))
    return min(times[0]), min(times[1])

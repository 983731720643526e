"""Placebo networks: the starting network's weights, each scaled by (1 + ``scale`` x N(0, 1)), nothing learned.

An end-to-end read is sensitive: a frame a little different is kept or fused differently, a view
lands a pixel elsewhere, and a page can flip between readable and not. Before/after on a few dozen
pages therefore moves even when the network did not get better or worse. Reading the same pages
with a few placebos shows how far it moves by chance; a tuned network's change means something only
where it leaves that spread (docs/finetune.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darkread.models.train.onnx_weights import load_onnx_model


def perturbed(weights: np.ndarray, rng: np.random.Generator, scale: float) -> np.ndarray:
    """``weights`` times (1 + ``scale`` x standard normal), element by element, in their own dtype."""
    return (weights * (1.0 + scale * rng.standard_normal(weights.shape))).astype(weights.dtype)


def write_placebo(base: str | Path, out: str | Path, *, seed: int, scale: float = 0.005) -> Path:
    """A copy of ``base`` (ONNX) whose floating-point weight tensors are perturbed; metadata (the ink
    temperature) is kept, so the edge reads it exactly as it reads ``base``."""
    import onnx
    from onnx import numpy_helper


    if not 0 < scale < 1:
        raise ValueError(f"--scale {scale}: must be between 0 and 1 (a relative perturbation, e.g. 0.005)")
    model = load_onnx_model(base)
    rng = np.random.default_rng(seed)
    for tensor in model.graph.initializer:
        weights = numpy_helper.to_array(tensor)
        if weights.dtype.kind == "f" and weights.size > 1:  # not shapes, not scalar constants
            tensor.CopyFrom(numpy_helper.from_array(perturbed(weights, rng, scale), tensor.name))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(model, str(out))
    return out

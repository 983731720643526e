"""Voxel grid -> binary ink image with the shipped ONNX U-Net (numpy + onnxruntime only).

The network outputs logits; the frame is ``logits > 0`` (sigmoid 0.5), so no sigmoid runs for a
binary frame. Ink mask convention: uint8, 1 = ink, 0 = paper. Where frames are averaged on the
glasses (the on-change mode's views), :meth:`Reconstructor.ink_probability` gives the calibrated
probability instead: one frame's doubt is information a binary mask throws away.

The window geometry and the bin count are the model's input shape ``[batch, bins, height,
width]``, read here once (:attr:`Reconstructor.voxel`); the pipeline, the uplink's ``hello`` and
the page stitcher take them from there, so a model trained for another window just works.

Session settings follow the measured single-core figures: full graph optimisation, a fixed
number of intra-op threads (1 = deterministic and fastest for this size), no spin-waiting
(spinning burns battery on the glasses between windows), the batch axis fixed at 1 for single
windows (static shapes: a third faster), and a few warm-up runs at load so the first real
window is not slowed by lazy allocation.
"""

from __future__ import annotations

import logging
import math
import os
from importlib import resources
from pathlib import Path

import numpy as np
import onnxruntime as ort

from darkread.edge.errors import ModelError
from darkread.edge.voxel import VoxelConfig

log = logging.getLogger(__name__)

MODEL_FILENAME = "binary_unet.onnx"
# The ink probability is sigmoid(logits / T). A network's T is stored in its ONNX metadata under
# this key (models/MODEL_CARD.md: how each was chosen); a network without it is taken as the
# full-resolution one trained on Dice alone, over-confident, with T = 1.5 (the log-loss minimum on
# 500 held-out synthetic windows: 0.137 against 0.143 at T = 1)
INK_TEMPERATURE_KEY = "ink_temperature"
INK_TEMPERATURE = 1.5


def default_model_path() -> Path:
    """The model shipped inside the ``darkread.models`` package."""
    return Path(str(resources.files("darkread.models").joinpath(MODEL_FILENAME)))


def _static_dims(dims: list[object]) -> tuple[int, ...] | None:
    return tuple(d if isinstance(d, int) else -1 for d in dims) if dims else None


def _load_session(path: Path, threads: int, batch_1: str | None = None) -> ort.InferenceSession:
    """An onnxruntime session with the single-core settings; ``batch_1`` names a free batch axis to fix at 1."""
    options = ort.SessionOptions()
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    options.log_severity_level = 3
    if batch_1 is not None:
        options.add_free_dimension_override_by_name(batch_1, 1)
    try:
        return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own untyped errors
        raise ModelError(f"cannot load reconstruction model {path}: {exc}") from exc


class Reconstructor:
    """Runs the binary reconstruction network on one voxel grid or a batch of them."""

    def __init__(
        self,
        model_path: str | os.PathLike[str] | None = None,
        *,
        threads: int = 1,
        warmup: int = 3,
        temperature: float | None = None,
    ) -> None:
        path = Path(model_path) if model_path is not None else default_model_path()
        if not path.is_file():
            raise ModelError(
                f"reconstruction model not found at {path}; reinstall darkread or pass the path of a "
                "binary_unet.onnx (make one with `darkread train all`)"
            )
        if threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        if temperature is not None and not temperature > 0:
            raise ValueError(f"temperature must be positive, got {temperature}")
        self._session = _load_session(path, threads)
        self.temperature = float(temperature) if temperature is not None else model_temperature(self._session, path)
        inputs, outputs = self._session.get_inputs(), self._session.get_outputs()
        if len(inputs) != 1 or len(outputs) != 1:
            raise ModelError(f"{path}: expected one input and one output, found {len(inputs)} and {len(outputs)}")
        in_dims = _static_dims(inputs[0].shape)
        out_dims = _static_dims(outputs[0].shape)
        if in_dims is None or len(in_dims) != 4 or min(in_dims[1:]) < 1:
            raise ModelError(f"{path}: input shape {inputs[0].shape}, expected [batch, bins, height, width] with fixed sizes")
        bins, height, width = in_dims[1:]
        if out_dims is None or len(out_dims) != 4 or out_dims[1:] != (1, height, width):
            raise ModelError(f"{path}: output shape {outputs[0].shape}, expected [batch, 1, {height}, {width}]")
        self.path = path
        self.voxel = VoxelConfig(bins=bins, height=height, width=width)
        self.input_shape: tuple[int, int, int] = self.voxel.shape
        self._input_name = inputs[0].name
        self._batch_fixed = in_dims[0] if in_dims[0] > 0 else None
        batch_dim = inputs[0].shape[0]
        # One window at a time (the edge) runs a session whose batch axis is fixed to 1: with every
        # shape known, onnxruntime folds the resize sizes and plans memory once (measured 3.1 ms
        # against 4.5 ms a window on the loaded development VM; logits agree to ~2e-6). Batches
        # keep the session with the free axis.
        self._single = (
            _load_session(path, threads, batch_1=batch_dim) if self._batch_fixed is None and isinstance(batch_dim, str) else None
        )
        self.input_window: np.ndarray | None = None
        if self._single is not None:
            self._bind_window(outputs[0].name)
        zeros = np.zeros((1, *self.input_shape), np.float32)
        for _ in range(max(0, warmup)):
            self._run(zeros)
        log.debug("loaded %s (threads=%d)", path, threads)

    def _bind_window(self, output_name: str) -> None:
        """``input_window``: one voxel grid the single-window session reads in place, its logits
        written into a buffer of ours (onnxruntime's I/O binding). A caller that bins straight into
        it (``voxel_grid(..., out=rec.input_window)``) spares the grid's allocation and the
        session's input and output copies per window."""
        assert self._single is not None
        self.input_window = np.zeros(self.input_shape, np.float32)
        self._output_window = np.zeros((1, 1, *self.input_shape[1:]), np.float32)
        binding = self._single.io_binding()
        binding.bind_input(self._input_name, "cpu", 0, np.float32, [1, *self.input_shape], self.input_window.ctypes.data)
        binding.bind_output(output_name, "cpu", 0, np.float32, list(self._output_window.shape), self._output_window.ctypes.data)
        self._binding = binding

    def _run_window(self) -> np.ndarray:
        """Logits [H, W] of ``input_window`` (a view of the output buffer: the next window overwrites it)."""
        assert self._single is not None
        self._single.run_with_iobinding(self._binding)
        return self._output_window[0, 0]

    def _run(self, batch: np.ndarray) -> np.ndarray:
        if self._batch_fixed is not None and batch.shape[0] != self._batch_fixed:
            return np.concatenate([self._run(batch[i : i + 1]) for i in range(batch.shape[0])])
        session = self._single if self._single is not None and batch.shape[0] == 1 else self._session
        (out,) = session.run(None, {self._input_name: batch})
        return out

    def logits(self, voxel: np.ndarray) -> np.ndarray:
        """[bins,H,W] -> float32 [H,W]; [B,bins,H,W] -> [B,H,W] (the model's input shape)."""
        if voxel is self.input_window and voxel is not None:
            return self._run_window().copy()
        array = np.asarray(voxel)
        single = array.ndim == 3
        if array.shape[-3:] != self.input_shape or array.ndim not in (3, 4):
            shape = ",".join(map(str, self.input_shape))
            raise ValueError(f"voxel grid must be [{shape}] or [B,{shape}], got {list(array.shape)}")
        batch = np.ascontiguousarray(array[None] if single else array, dtype=np.float32)
        if batch.shape[0] == 0:
            return np.zeros((0, *self.input_shape[1:]), np.float32)
        out = self._run(batch)[:, 0]
        return out[0] if single else out

    def _logits_now(self, voxel: np.ndarray) -> np.ndarray:
        """Logits of ``voxel``; of the bound window in place (no copy) when it is ``input_window``."""
        return self._run_window() if voxel is self.input_window and voxel is not None else self.logits(voxel)

    def ink_probability(self, voxel: np.ndarray) -> np.ndarray:
        """Calibrated ink probability float32 in [0, 1] (``> 0.5`` exactly where ``__call__`` says ink)."""
        return probability_from_logits(self._logits_now(voxel), self.temperature)

    def __call__(self, voxel: np.ndarray) -> np.ndarray:
        """Binary ink mask (uint8, 1 = ink) of the same leading shape as ``logits``."""
        return (self._logits_now(voxel) > 0).astype(np.uint8)


def model_temperature(session: ort.InferenceSession, path: Path) -> float:
    """The ink temperature a network carries in its metadata (``INK_TEMPERATURE`` when it has none)."""
    stored = session.get_modelmeta().custom_metadata_map.get(INK_TEMPERATURE_KEY)
    if stored is None:
        return INK_TEMPERATURE
    try:
        value = float(stored)
    except ValueError:
        value = math.nan
    if not value > 0 or math.isinf(value):
        raise ModelError(f"{path}: metadata {INK_TEMPERATURE_KEY}={stored!r} is not a positive number; "
                         "store one with `darkread train calibrate --store T`")
    return value


def probability_from_logits(logits: np.ndarray, temperature: float = INK_TEMPERATURE) -> np.ndarray:
    """sigmoid(logits / temperature) as float32, without overflow warnings for large logits."""
    z = np.asarray(logits, np.float32) * np.float32(-1.0 / temperature)
    np.clip(z, -60.0, 60.0, out=z)
    np.exp(z, out=z)
    z += 1.0
    np.reciprocal(z, out=z)
    return z

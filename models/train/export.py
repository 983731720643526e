"""Export the trained network to ONNX (fp32) and a static-int8 QDQ variant.

Static QDQ quantisation, calibrated on real voxel grids from the dataset, is the int8 form that
is fast for convolutions in onnxruntime; dynamic quantisation falls back to ConvInteger and is
several times *slower* than fp32 for this network, so it is not offered.
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch

from darkread.models.train.net import INPUT_SHAPE, BinaryUNet

log = logging.getLogger(__name__)

OPSET = 17
INPUT_NAME = "voxel"
OUTPUT_NAME = "logits"


def export_onnx(model: BinaryUNet, path: str | Path) -> Path:
    """Write ``model`` (eval mode, BatchNorm folded by the exporter) with a dynamic batch axis."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    model = model.eval()
    example = torch.zeros(1, *INPUT_SHAPE)
    with torch.no_grad():
        out_shape = tuple(model(example).shape)
        torch.onnx.export(
            model,
            (example,),
            str(out),
            input_names=[INPUT_NAME],
            output_names=[OUTPUT_NAME],
            opset_version=OPSET,
            dynamic_axes={INPUT_NAME: {0: "batch"}, OUTPUT_NAME: {0: "batch"}},
            do_constant_folding=True,
            dynamo=False,
        )
    import onnx

    graph_model = onnx.load(str(out))
    # the exporter leaves a pixel shuffle's output sizes symbolic; the edge needs them fixed (all but the batch)
    for dim, size in zip(list(graph_model.graph.output[0].type.tensor_type.shape.dim)[1:], out_shape[1:]):
        dim.Clear()
        dim.dim_value = int(size)
    onnx.checker.check_model(graph_model)
    onnx.save(graph_model, str(out))
    log.info("exported %s (%.0f kB)", out, out.stat().st_size / 1024)
    return out


class _VoxelReader:
    """onnxruntime CalibrationDataReader over an array of voxel grids."""

    def __init__(self, voxels: np.ndarray) -> None:
        self._batches: Iterator[dict[str, np.ndarray]] = (
            {INPUT_NAME: voxels[i : i + 1].astype(np.float32)} for i in range(len(voxels))
        )

    def get_next(self) -> dict[str, np.ndarray] | None:
        return next(self._batches, None)


def quantize_int8(fp32_path: str | Path, int8_path: str | Path, calibration_voxels: np.ndarray) -> Path:
    """Static QDQ int8 (uint8 activations, per-channel int8 weights), calibrated on ``calibration_voxels``."""
    from onnxruntime.quantization import (
        CalibrationDataReader,
        QuantFormat,
        QuantType,
        quantize_static,
    )
    from onnxruntime.quantization.shape_inference import quant_pre_process

    if len(calibration_voxels) == 0:
        raise ValueError("int8 calibration needs at least one voxel grid")

    class Reader(_VoxelReader, CalibrationDataReader):
        pass

    out = Path(int8_path)
    with tempfile.TemporaryDirectory() as tmp:
        prepared = Path(tmp) / "prepared.onnx"
        quant_pre_process(str(fp32_path), str(prepared), skip_symbolic_shape=True)
        quantize_static(
            str(prepared),
            str(out),
            Reader(calibration_voxels),
            quant_format=QuantFormat.QDQ,
            activation_type=QuantType.QUInt8,
            weight_type=QuantType.QInt8,
            per_channel=True,
        )
    log.info("quantised %s -> %s (%d calibration windows)", fp32_path, out, len(calibration_voxels))
    return out

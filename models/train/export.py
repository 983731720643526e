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
from typing import TYPE_CHECKING

import numpy as np
import torch
from darkread.models.train.net import INPUT_SHAPE, BinaryUNet

if TYPE_CHECKING:
    import onnx

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

    graph = resize_as_matmul(onnx.load(str(out)))
    onnx.checker.check_model(graph)
    onnx.save(graph, str(out))
    log.info("exported %s (%.0f kB)", out, out.stat().st_size / 1024)
    return out


def linear_resize_matrix(n_in: int, n_out: int) -> np.ndarray:
    """[n_out, n_in] weights of ONNX Resize along one axis (mode linear, half_pixel, edges clamped)."""
    x = np.clip((np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5, 0.0, n_in - 1)
    low = np.floor(x).astype(np.intp)
    high = np.minimum(low + 1, n_in - 1)
    frac = x - low
    m = np.zeros((n_out, n_in))
    np.add.at(m, (np.arange(n_out), low), 1.0 - frac)
    np.add.at(m, (np.arange(n_out), high), frac)
    return m.astype(np.float32)


def resize_as_matmul(model: onnx.ModelProto) -> onnx.ModelProto:
    """The same network with every bilinear Resize as two constant matrix products.

    Why: at this size onnxruntime's linear Resize costs about a fifth of the net's time on one core;
    rows @ X @ columns is the same interpolation (to float rounding) at half the cost. The window
    is fixed (only the batch is dynamic), so each Resize's sizes are read from one probe run; the
    shape arithmetic that fed them is dropped. Other nodes, and the Conv order fine-tuning reads
    weights in, are untouched.
    """
    import onnx
    import onnxruntime as ort
    from onnx import helper, numpy_helper

    resizes = [n for n in model.graph.node if n.op_type == "Resize"]
    for node in resizes:
        attrs = {a.name: helper.get_attribute_value(a) for a in node.attribute}
        if attrs.get("mode") != b"linear" or attrs.get("coordinate_transformation_mode") != b"half_pixel":
            raise ValueError(f"{node.name}: only linear half_pixel Resize can become matrix products")
    if not resizes:
        return model
    probe = onnx.ModelProto()
    probe.CopyFrom(model)
    names = [name for node in resizes for name in (node.input[0], node.output[0])]
    probe.graph.output.extend(helper.make_tensor_value_info(name, onnx.TensorProto.FLOAT, None) for name in names)
    session = ort.InferenceSession(probe.SerializeToString(), providers=["CPUExecutionProvider"])
    first = session.get_inputs()[0]
    shape = [1, *INPUT_SHAPE] if first.name == INPUT_NAME else [d if isinstance(d, int) else 1 for d in first.shape]
    values = session.run(names, {first.name: np.zeros(shape, np.float32)})
    shapes = {name: v.shape for name, v in zip(names, values, strict=True)}

    graph = model.graph
    nodes = []
    for node in graph.node:
        if node.op_type != "Resize":
            nodes.append(node)
            continue
        (h, w), (big_h, big_w) = shapes[node.input[0]][2:], shapes[node.output[0]][2:]
        rows = numpy_helper.from_array(linear_resize_matrix(h, big_h), f"{node.name}/rows")
        columns = numpy_helper.from_array(np.ascontiguousarray(linear_resize_matrix(w, big_w).T), f"{node.name}/columns")
        graph.initializer.extend([rows, columns])
        across = f"{node.name}/across"
        nodes.append(helper.make_node("MatMul", [node.input[0], columns.name], [across], name=f"{node.name}/MatMul_columns"))
        nodes.append(helper.make_node("MatMul", [rows.name, across], [node.output[0]], name=f"{node.name}/MatMul_rows"))
    needed = {o.name for o in graph.output}
    live = []
    for node in reversed(nodes):  # nodes are in run order: walk back from the outputs
        if any(o in needed for o in node.output):
            live.append(node)
            needed.update(i for i in node.input if i)
    del graph.node[:]
    graph.node.extend(reversed(live))
    kept = [t for t in graph.initializer if t.name in needed]
    del graph.initializer[:]
    graph.initializer.extend(kept)
    return model


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

    import onnx

    interpolation = [n.name for n in onnx.load(str(fp32_path)).graph.node if n.op_type == "MatMul"]
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
            nodes_to_exclude=interpolation,  # resize_as_matmul's fixed weights stay exact
        )
    log.info("quantised %s -> %s (%d calibration windows)", fp32_path, out, len(calibration_voxels))
    return out

"""The shipped ONNX network back in torch, so fine-tuning can start from exactly what ships.

No .pt checkpoint ships, only ``binary_unet.onnx``, whose exporter folded every BatchNorm into the
convolution before it. The torch net keeps its BatchNorms, so each folded convolution goes back as
(weight, bias) = (conv weight, identity BatchNorm with beta = folded bias): running mean 0, running
variance 1, gamma sqrt(1 + eps), so the BatchNorm in eval mode is exactly ``x + beta``. The
convolutions are matched in the order the graph runs them (the exporter traces ``forward``), which
is the order torch calls its Conv2d modules; every shape is checked, and callers can confirm the
round trip on a window with ``max_output_difference``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from darkread.models.train.net import INPUT_SHAPE, BinaryUNet, NetConfig


class OnnxWeightsError(ValueError):
    """The ONNX file is not a network of this architecture."""


def onnx_convolutions(path: str | Path) -> list[tuple[str, np.ndarray, np.ndarray | None]]:
    """(node name, weight, bias or None) of every Conv node, in graph order."""
    return [(node.name, weight, bias) for node, weight, bias in _conv_nodes(path)]


def load_onnx_model(path: str | Path) -> Any:
    """The ``onnx.ModelProto`` in ``path``; OnnxWeightsError naming the file when it is missing,
    truncated or not ONNX at all."""
    import onnx

    try:
        return onnx.load(str(path))
    except (OSError, onnx.onnx_cpp2py_export.checker.ValidationError) as exc:
        raise OnnxWeightsError(f"{path}: not a readable ONNX model ({exc})") from None
    except Exception as exc:  # protobuf DecodeError and friends: a file that is not ONNX at all
        raise OnnxWeightsError(f"{path}: not an ONNX model ({type(exc).__name__})") from None


def _conv_nodes(path: str | Path) -> list[tuple[Any, np.ndarray, np.ndarray | None]]:
    """(node, weight, bias or None) of every Conv node, in graph order: the file read once."""
    from onnx import numpy_helper

    graph = load_onnx_model(path).graph
    inits = {i.name: numpy_helper.to_array(i) for i in graph.initializer}
    convs = []
    for node in graph.node:
        if node.op_type != "Conv":
            continue
        if len(node.input) < 2 or node.input[1] not in inits:
            raise OnnxWeightsError(f"{path}: convolution {node.name} has no constant weight")
        bias = inits.get(node.input[2]) if len(node.input) > 2 else None
        convs.append((node, inits[node.input[1]], bias))
    return convs


def conv_order(model: nn.Module) -> list[tuple[nn.Conv2d, nn.BatchNorm2d | None]]:
    """The model's Conv2d modules in call order, each with the BatchNorm that follows it (if any)."""
    following: dict[int, nn.BatchNorm2d] = {}
    for module in model.modules():
        if isinstance(module, nn.Sequential):
            layers = list(module)
            for a, b in zip(layers, layers[1:]):
                if isinstance(a, nn.Conv2d) and isinstance(b, nn.BatchNorm2d):
                    following[id(a)] = b
    called: list[nn.Conv2d] = []
    hooks = [m.register_forward_hook(lambda mod, _i, _o: called.append(mod)) for m in model.modules() if isinstance(m, nn.Conv2d)]
    try:
        with torch.no_grad():
            model.eval()(torch.zeros(1, *INPUT_SHAPE))
    finally:
        for h in hooks:
            h.remove()
    return [(conv, following.get(id(conv))) for conv in called]


def load_onnx_weights(model: BinaryUNet, path: str | Path, shared_only: bool = False) -> BinaryUNet:
    """Copy the folded weights of ``path`` into ``model`` (in place; returned in eval mode).

    ``shared_only``: ``model`` may end differently (another head): the leading convolutions whose
    shapes agree are copied, the rest keep their fresh weights."""
    convs = onnx_convolutions(path)
    slots = conv_order(model)
    if shared_only:
        shared = next((k for k, ((_, weight, _), (conv, _)) in enumerate(zip(convs, slots))
                       if tuple(weight.shape) != tuple(conv.weight.shape)), min(len(convs), len(slots)))
        if shared == 0:
            raise OnnxWeightsError(f"{path}: its first convolution does not fit the network; not this architecture")
        convs, slots = convs[:shared], slots[:shared]
    if len(convs) != len(slots):
        raise OnnxWeightsError(f"{path}: {len(convs)} convolutions, the network has {len(slots)}; not this architecture")
    with torch.no_grad():
        for (name, weight, bias), (conv, bn) in zip(convs, slots):
            if tuple(weight.shape) != tuple(conv.weight.shape):
                raise OnnxWeightsError(f"{path}: {name} has weight {tuple(weight.shape)}, the network expects "
                                       f"{tuple(conv.weight.shape)}; not this architecture or these widths")
            conv.weight.copy_(torch.from_numpy(np.array(weight)))
            b = np.zeros(weight.shape[0], np.float32) if bias is None else bias
            if bn is not None:
                assert bn.running_mean is not None and bn.running_var is not None  # our BatchNorm2d layers track running statistics
                bn.running_mean.zero_()
                bn.running_var.fill_(1.0)
                bn.weight.fill_(float(np.sqrt(1.0 + bn.eps)))
                bn.bias.copy_(torch.from_numpy(np.array(b)))
            elif conv.bias is not None:
                conv.bias.copy_(torch.from_numpy(np.array(b)))
            elif np.any(b):
                raise OnnxWeightsError(f"{path}: {name} has a bias the network has no place for")
    return model.eval()


def onnx_config(path: str | Path) -> NetConfig:
    """The ``NetConfig`` of the network in ``path``, read from its convolutions in graph order: the
    stem, then per encoder scale a strided convolution and its separable blocks (a depthwise 3x3
    and a pointwise 1x1 each), then the decoder (a 1x1 projection that follows no depthwise one);
    the head gives four sub-pixel logits ("shuffle") or one ("full")."""
    import onnx

    nodes = _conv_nodes(path)
    convs = []  # (stride, group, kernel, output channels)
    for node, weight, _ in nodes:
        attributes = {a.name: onnx.helper.get_attribute_value(a) for a in node.attribute}
        convs.append((list(attributes.get("strides", [1, 1]))[0], attributes.get("group", 1), int(weight.shape[2]), int(weight.shape[0])))
    widths, blocks = [convs[0][3]], []
    for k in range(1, len(convs)):
        stride, group, kernel, out = convs[k]
        if stride == 2:
            widths.append(out)  # the next scale
            blocks.append(0)
        elif group > 1 and blocks:
            blocks[-1] += 1  # a separable block's depthwise convolution
        elif kernel == 1 and convs[k - 1][1] == 1:
            break  # a 1x1 after no depthwise one: the decoder's first projection
    if len(widths) != 4:
        raise OnnxWeightsError(f"{path}: {len(widths)} scales found, the network has 4; not this architecture")
    return NetConfig(widths=(widths[0], widths[1], widths[2], widths[3]), blocks=(blocks[0], blocks[1], blocks[2]),
                     in_channels=int(nodes[0][1].shape[1]),
                     head="shuffle" if convs[-1][3] == 4 else "full")


def model_from_onnx(path: str | Path, config: NetConfig | None = None) -> BinaryUNet:
    """A torch BinaryUNet computing what ``path`` computes (``onnx_config``: its widths, blocks and
    head, unless ``config`` says otherwise); with a ``config`` of another head, one that shares its layers up to that head (the
    head fresh: a start for training it)."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"{path}: no such model file")
    own = onnx_config(path)
    model = BinaryUNet(config or own)
    return load_onnx_weights(model, path, shared_only=model.config.head != own.head)


def max_output_difference(model: BinaryUNet, path: str | Path, voxels: np.ndarray) -> float:
    """Largest |torch logit - onnxruntime logit| on ``voxels`` [n,4,100,200]: the round-trip check."""
    import onnxruntime as ort

    x = np.ascontiguousarray(voxels, np.float32)
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    ref = session.run(None, {session.get_inputs()[0].name: x})[0]
    with torch.no_grad():
        got = model.eval()(torch.from_numpy(x)).numpy()
    return float(np.abs(got - ref).max())

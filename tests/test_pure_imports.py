"""The pure layers import light: what the glasses and the wire need must not drag in the web stack,
the model runtime or the other side (the import graph as Python really builds it)."""

from __future__ import annotations

import subprocess
import sys

import pytest

WEB_AND_MODELS = {"torch", "onnxruntime", "fastapi", "starlette", "uvicorn", "rapidocr"}


@pytest.mark.parametrize(
    ("modules", "forbidden"),
    [
        # the glasses stitch too: numpy, OpenCV and the standard library only
        (["darkread.stitch"], WEB_AND_MODELS | {"PIL", "matplotlib", "scipy"}),
        # the wire and the shared records: numpy and msgpack only, neither side nor OpenCV
        (["darkread.proto.messages", "darkread.core.errors", "darkread.core.frame_record", "darkread.core.mask_bits"],
         WEB_AND_MODELS | {"darkread.edge", "darkread.cloud", "darkread.stitch", "cv2"}),
    ],
)
def test_pure_layers_import_light(modules: list[str], forbidden: set[str]) -> None:
    code = f"import sys, {', '.join(modules)}\nprint(sorted(m for m in {sorted(forbidden)!r} if m in sys.modules))\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60)
    assert out.stdout.strip() == "[]"

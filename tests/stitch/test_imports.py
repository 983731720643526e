"""The glasses stitch too: the package must import with numpy, OpenCV and the standard library only."""

from __future__ import annotations

import subprocess
import sys


def test_stitch_imports_no_web_stack_torch_or_onnxruntime() -> None:
    code = (
        "import sys, darkread.stitch\n"
        "heavy = {'torch', 'onnxruntime', 'fastapi', 'starlette', 'uvicorn', 'PIL', 'matplotlib', 'scipy', 'rapidocr'}\n"
        "print(sorted(heavy & {name.split('.')[0] for name in sys.modules}))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60)
    assert out.stdout.strip() == "[]"

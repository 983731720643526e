"""The module map of docs/architecture.md, enforced: which component may import which.

Every import statement in the shipped code (module level or inside a function, where the heavy
imports of the command line live) is parsed with ``ast`` and checked against the allowed edges.
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# folder -> component
FOLDERS = {"proto": "proto", "stitch": "stitch", "edge": "edge", "cloud": "cloud", "models": "models", "darkread": "app"}
# the small pure modules of the darkread package every component shares: the version, the error
# tree's base, the frame record, the mask bit layout, the image codec
CORE = {"darkread", "darkread.errors", "darkread.frame_record", "darkread.mask_bits", "darkread.image_codec", "darkread.json_file"}

# component -> the darkread components it may import
ALLOWED: dict[str, set[str]] = {
    "core": {"core"},
    "proto": {"proto", "core"},
    "stitch": {"stitch", "core"},
    "edge": {"edge", "proto", "stitch", "core"},
    "cloud": {"cloud", "proto", "stitch", "core"},
    "models": {"models", "edge", "proto", "stitch", "core", "app"},  # app: darkread.paths, the latency benchmark
    "app": {"app", "core", "proto", "stitch", "edge", "cloud", "models"},
}

# third-party packages a component must not import, whatever extras are installed here
WEB_AND_OCR = {"fastapi", "uvicorn", "starlette", "pydantic", "pydantic_settings", "httpx", "prometheus_client",
               "rapidocr", "pytesseract", "tesserocr", "symspellpy", "pocketsphinx"}
FORBIDDEN: dict[str, set[str]] = {
    "edge": WEB_AND_OCR | {"torch"},  # the glasses run without a web server, OCR or PyTorch
    "cloud": {"usb", "torch", "numba"},  # no USB stack, no training stack
}
# pure components: the standard library and these only
PURE_THIRD_PARTY: dict[str, set[str]] = {
    "core": {"numpy", "cv2"},
    "proto": {"msgpack", "numpy", "PIL"},  # PIL: the CCITT G4 codec of stitched pages (libtiff)
    "stitch": {"numpy", "cv2"},
}


def component_of_file(path: Path) -> str:
    rel = path.relative_to(ROOT)
    if rel.parts[0] == "darkread":
        module = ".".join(rel.with_suffix("").parts).removesuffix(".__init__")
        return "core" if module in CORE else "app"
    return FOLDERS[rel.parts[0]]


def component_of_module(module: str) -> str | None:
    """``darkread.edge.pipeline`` -> "edge"; None for anything outside darkread."""
    parts = module.split(".")
    if parts[0] != "darkread":
        return None
    if ".".join(parts[:2]) in CORE:
        return "core"
    return parts[1] if parts[1] in FOLDERS and parts[1] != "darkread" else "app"


def shipped_files() -> Iterator[Path]:
    for folder in FOLDERS:
        if (ROOT / folder).is_dir():
            yield from sorted((ROOT / folder).rglob("*.py"))


def imports(path: Path) -> Iterator[tuple[int, str]]:
    """(line, absolute module) of every import in ``path``; relative ones stay in their package."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.lineno, node.module


def violations() -> list[str]:
    stdlib = set(sys.stdlib_module_names)
    found = []
    for path in shipped_files():
        source = component_of_file(path)
        where = path.relative_to(ROOT)
        for line, module in imports(path):
            target = component_of_module(module)
            top = module.split(".")[0]
            if target is not None:
                if target not in ALLOWED[source]:
                    found.append(f"{where}:{line}: {source} imports {module} ({target})")
            elif top in FORBIDDEN.get(source, ()):
                found.append(f"{where}:{line}: {source} imports {top}")
            elif source in PURE_THIRD_PARTY and top not in stdlib and top not in PURE_THIRD_PARTY[source]:
                found.append(f"{where}:{line}: {source} is pure but imports {top}")
    return found


def test_components_import_only_what_the_module_map_allows() -> None:
    assert violations() == []


def test_the_rules_see_every_component() -> None:
    seen = {component_of_file(path) for path in shipped_files()}
    assert seen == set(ALLOWED)


@pytest.mark.parametrize(
    ("source", "module", "allowed"),
    [("edge", "darkread.cloud.app", False), ("cloud", "darkread.edge.sources.evk4.camera", False),
     ("cloud", "darkread.stitch", True), ("proto", "darkread.edge.events", False), ("edge", "darkread.proto", True),
     ("stitch", "darkread.frame_record", True), ("proto", "darkread.cli", False), ("edge", "darkread.errors", True)],
)
def test_the_rules_themselves(source: str, module: str, allowed: bool) -> None:
    assert (component_of_module(module) in ALLOWED[source]) is allowed

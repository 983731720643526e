"""The module map of docs/architecture.md, enforced: which component may import which.

Every import statement in the installed code (module level or inside a function, where the heavy
imports of the command line live) is parsed with ``ast`` and checked against the allowed edges.
The layers are read from the folders: ``darkread/core/`` is the core, the rest of ``darkread/`` the
application (the command line and ``darkread read``), each top-level folder its component, and
``lab/`` (installed as ``darkread.lab``) the lab, which nothing outside it imports.
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# top-level folder -> component (darkread/core/ and the package's own __init__ are the core)
FOLDERS = {"proto": "proto", "stitch": "stitch", "edge": "edge", "cloud": "cloud", "models": "models", "lab": "lab",
           "darkread": "app"}
PRODUCT = {"core", "proto", "stitch", "edge", "cloud", "models", "app"}

# component -> the darkread components it may import
ALLOWED: dict[str, set[str]] = {
    "core": {"core"},
    "proto": {"proto", "core"},
    "stitch": {"stitch", "core"},
    "edge": {"edge", "proto", "stitch", "core"},
    "cloud": {"cloud", "proto", "stitch", "core"},
    "models": {"models", "edge", "proto", "stitch", "core"},  # what makes and ships the network: nothing above it
    "app": {"app", "core", "proto", "stitch", "edge", "cloud", "models"},
    "lab": {"lab", "app", "core", "proto", "stitch", "edge", "cloud", "models"},
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
    "core": {"numpy", "cv2", "jiwer"},  # jiwer: the text metrics (a core dependency)
    "proto": {"msgpack", "numpy", "PIL"},  # PIL: the CCITT G4 codec of stitched pages (libtiff)
    "stitch": {"numpy", "cv2"},
}


def module_of_file(path: Path) -> str:
    """``edge/pipeline.py`` -> ``darkread.edge.pipeline``; ``darkread/core/errors.py`` -> ``darkread.core.errors``."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    dotted = ".".join(parts if parts[0] == "darkread" else ("darkread", *parts))
    return dotted.removesuffix(".__init__")


def component_of_file(path: Path) -> str:
    component = component_of_module(module_of_file(path))
    assert component is not None
    return component


def component_of_module(module: str) -> str | None:
    """``darkread.edge.pipeline`` -> "edge", ``darkread.core.errors`` -> "core"; None outside darkread."""
    parts = module.split(".")
    if parts[0] != "darkread":
        return None
    if len(parts) == 1 or parts[1] in ("core", "__version__"):
        return "core"  # the package itself holds only the version
    return parts[1] if parts[1] in FOLDERS and parts[1] != "darkread" else "app"


def shipped_files() -> Iterator[Path]:
    for folder in FOLDERS:
        if (ROOT / folder).is_dir():
            yield from sorted((ROOT / folder).rglob("*.py"))


def imports(path: Path) -> Iterator[tuple[int, str]]:
    """(line, absolute name) of every import in ``path``, relative ones resolved; ``from a import b``
    gives ``a.b`` (a module, or a name inside module ``a``)."""
    package = module_of_file(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            base = [] if node.level == 0 else package[: len(package) - node.level + 1]
            module = ".".join([*base, *([node.module] if node.module else [])])
            for alias in node.names:  # ``from package import module`` names the module itself
                yield node.lineno, f"{module}.{alias.name}"


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


def test_nothing_outside_the_lab_imports_it() -> None:
    assert not [rule for rule, allowed in ALLOWED.items() if rule in PRODUCT and "lab" in allowed]


def import_graph() -> dict[str, set[str]]:
    """module -> the darkread modules it imports (a ``from package import name`` counts as the package)."""
    modules = {module_of_file(path): path for path in shipped_files()}
    graph: dict[str, set[str]] = {}
    for module, path in modules.items():
        targets = set()
        for _, imported in imports(path):
            while imported and imported not in modules:
                imported = imported.rpartition(".")[0]
            if imported and imported != module:
                targets.add(imported)
        graph[module] = targets
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_no_module_imports_itself_through_others() -> None:
    """No circle of imports, module level or inside functions: each layer reads top to bottom."""
    assert circles(import_graph()) == []


def test_circles_are_found() -> None:
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


@pytest.mark.parametrize(
    ("source", "module", "allowed"),
    [("edge", "darkread.cloud.app", False), ("cloud", "darkread.edge.sources.evk4.camera", False),
     ("cloud", "darkread.stitch", True), ("proto", "darkread.edge.events", False), ("edge", "darkread.proto", True),
     ("stitch", "darkread.core.frame_record", True), ("proto", "darkread.cli", False), ("edge", "darkread.core.errors", True)],
)
def test_the_rules_themselves(source: str, module: str, allowed: bool) -> None:
    assert (component_of_module(module) in ALLOWED[source]) is allowed


# Where an import may sit inside a function. Command-line modules import each handler's stack when
# the handler runs (so `darkread --help` and `darkread edge` load no web, USB or training stack);
# these packages are optional (an extra, or absent on the glasses) or heavy to load; any other
# in-function import says why in a comment on its line or just above it.
COMMAND_LINE_MODULES = {"darkread/read.py", "edge/inspect.py"}
OPTIONAL_OR_HEAVY = {
    "torch", "onnx", "onnxruntime", "hesim3d", "rapidocr", "pytesseract", "tesserocr", "eyekit", "pocketsphinx",
    "matplotlib", "usb", "psycopg", "psycopg_pool", "selenium", "scipy", "symspellpy", "aria", "projectaria_tools",
    "evt3", "uvicorn", "httpx", "websockets", "fastapi", "pydantic", "tqdm", "PIL", "numba",
}


def unexplained_function_imports(path: Path) -> Iterator[str]:
    rel = path.relative_to(ROOT).as_posix()
    if path.name == "cli.py" or rel in COMMAND_LINE_MODULES:
        return
    lines = path.read_text(encoding="utf-8").splitlines()
    tree = ast.parse("\n".join(lines), rel)
    for function in ast.walk(tree):
        if not isinstance(function, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        for node in ast.walk(function):
            if not isinstance(node, ast.Import | ast.ImportFrom):
                continue
            name = node.names[0].name if isinstance(node, ast.Import) else (node.module or "")
            relative = isinstance(node, ast.ImportFrom) and node.level > 0
            if not relative and name.split(".")[0] in OPTIONAL_OR_HEAVY:
                continue
            above = lines[max(0, node.lineno - 4) : node.lineno - 1]
            said = "#" in lines[node.lineno - 1] or any(line.strip().startswith("#") for line in above)
            if not said:
                yield f"{rel}:{node.lineno}: import {name} inside {function.name}() without a reason"


def test_imports_inside_functions_say_why() -> None:
    assert [line for path in shipped_files() for line in unexplained_function_imports(path)] == []

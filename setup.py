"""Maps the top-level component folders into the single ``darkread`` namespace."""

from pathlib import Path

from setuptools import setup

ROOT = Path(__file__).parent
COMPONENTS = ("edge", "cloud", "proto", "stitch", "models", "lab")


def _packages() -> tuple[list[str], dict[str, str]]:
    packages, package_dir = ["darkread"], {"darkread": "darkread"}
    for top in ("darkread", *COMPONENTS):
        for init in sorted((ROOT / top).rglob("__init__.py")):
            rel = init.parent.relative_to(ROOT)
            dotted = ".".join(rel.parts)
            name = dotted if top == "darkread" else f"darkread.{dotted}"
            if name not in packages:
                packages.append(name)
            package_dir[name] = rel.as_posix()
    return packages, package_dir


PACKAGES, PACKAGE_DIR = _packages()
setup(packages=PACKAGES, package_dir=PACKAGE_DIR)

"""Maps the top-level component folders into the single ``darkread`` namespace.

Folders of package data (templates, fonts, the sample recording, ...) are listed as packages too
(namespace packages without ``__init__.py``): setuptools installs the files of a listed package
only, and warns about every importable folder the ``packages`` list leaves out.
"""

import warnings
from pathlib import Path

from setuptools import setup
from setuptools.warnings import InformationOnly

# An editable install notes that folders named like the package may shadow it; the component
# folders mapped into darkread.* are that layout on purpose, so the note is not for every set-up.
warnings.filterwarnings("ignore", message="Editable installation", category=InformationOnly)

ROOT = Path(__file__).parent
COMPONENTS = ("edge", "cloud", "proto", "stitch", "models", "lab")
NOT_PACKAGES = {"__pycache__"}


def _folders(top: Path) -> list[Path]:
    """``top`` and every folder below it that can hold modules or data (no caches, no hidden ones)."""
    found = [top]
    for child in sorted(path for path in top.iterdir() if path.is_dir()):
        if child.name not in NOT_PACKAGES and not child.name.startswith(".") and not child.name.endswith(".egg-info"):
            found.extend(_folders(child))
    return found


def _packages() -> tuple[list[str], dict[str, str]]:
    packages, package_dir = [], {}
    for top in ("darkread", *COMPONENTS):
        for folder in _folders(ROOT / top):
            rel = folder.relative_to(ROOT)
            dotted = ".".join(rel.parts)
            name = dotted if top == "darkread" else f"darkread.{dotted}"
            packages.append(name)
            package_dir[name] = rel.as_posix()
    return packages, package_dir


PACKAGES, PACKAGE_DIR = _packages()
setup(packages=PACKAGES, package_dir=PACKAGE_DIR)

"""Font families for synthetic pages, with an explicit train / held-out split.

DejaVu, STIX and Computer Modern come from matplotlib's bundled fonts, Roboto ships in ``darkread/models/fonts``; a
set-up therefore never depends on fonts installed by hand. Roboto (a sans face the model never
sees in training) is held out for validation.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

SHIPPED_FONTS_DIR = Path(__file__).resolve().parent.parent / "fonts"


@dataclass(frozen=True)
class FontFace:
    family: str
    bold: bool
    filename: str
    source: str  # "matplotlib" or "shipped"

    @property
    def name(self) -> str:
        return f"{self.family} Bold" if self.bold else self.family

    @property
    def path(self) -> Path:
        if self.source == "shipped":
            return SHIPPED_FONTS_DIR / self.filename
        return _matplotlib_ttf_dir() / self.filename


FACES: tuple[FontFace, ...] = (
    FontFace("DejaVu Sans", False, "DejaVuSans.ttf", "matplotlib"),
    FontFace("DejaVu Sans", True, "DejaVuSans-Bold.ttf", "matplotlib"),
    FontFace("DejaVu Serif", False, "DejaVuSerif.ttf", "matplotlib"),
    FontFace("DejaVu Serif", True, "DejaVuSerif-Bold.ttf", "matplotlib"),
    FontFace("STIX General", False, "STIXGeneral.ttf", "matplotlib"),
    FontFace("STIX General", True, "STIXGeneralBol.ttf", "matplotlib"),
    FontFace("Roboto", False, "Roboto-Regular.ttf", "shipped"),
    FontFace("Roboto", True, "Roboto-Bold.ttf", "shipped"),
    FontFace("DejaVu Sans Mono", False, "DejaVuSansMono.ttf", "matplotlib"),
    FontFace("DejaVu Sans Mono", True, "DejaVuSansMono-Bold.ttf", "matplotlib"),
    FontFace("Computer Modern Sans", False, "cmss10.ttf", "matplotlib"),
    FontFace("Computer Modern Roman", False, "cmr10.ttf", "matplotlib"),
    FontFace("Computer Modern Roman", True, "cmb10.ttf", "matplotlib"),
)

TRAIN_FAMILIES: tuple[str, ...] = ("DejaVu Sans", "DejaVu Serif", "STIX General")
HELD_OUT_FAMILIES: tuple[str, ...] = ("Roboto",)
# never in training nor in the validation sets: the font of the shifted sensor regime (issue 17)
SHIFTED_FAMILIES: tuple[str, ...] = ("DejaVu Sans Mono",)
# more shapes for training sets made with --more-fonts (matplotlib's Computer Modern, offline): a
# network that has seen five families leans less on the three it knows (the shipped one's dim windows)
MORE_TRAIN_FAMILIES: tuple[str, ...] = ("Computer Modern Sans", "Computer Modern Roman")


@lru_cache(maxsize=1)
def _matplotlib_ttf_dir() -> Path:
    import matplotlib

    return Path(matplotlib.get_data_path()) / "fonts" / "ttf"


def faces_for(split: str) -> tuple[FontFace, ...]:
    """Faces of the ``"train"``, ``"held_out"`` or ``"shifted"`` families (``"all"``: train and held out;
    ``"train_more"``: the training families and ``MORE_TRAIN_FAMILIES``), in ``FACES`` order."""
    if split == "train":
        families = TRAIN_FAMILIES
    elif split == "train_more":
        families = TRAIN_FAMILIES + MORE_TRAIN_FAMILIES
    elif split == "held_out":
        families = HELD_OUT_FAMILIES
    elif split == "all":
        families = TRAIN_FAMILIES + HELD_OUT_FAMILIES
    elif split == "shifted":
        families = SHIFTED_FAMILIES
    else:
        raise ValueError(f"unknown font split {split!r}; use 'train', 'train_more', 'held_out', 'shifted' or 'all'")
    return tuple(f for f in FACES if f.family in families)


def face_by_name(name: str) -> FontFace:
    """Look a face up by ``FontFace.name`` (e.g. ``"DejaVu Serif Bold"``)."""
    for face in FACES:
        if face.name == name:
            return face
    raise ValueError(f"unknown font {name!r}; known: {', '.join(f.name for f in FACES)}")

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


FONT_SPLITS = ("train", "train_more", "held_out", "all", "shifted")


def families_of(split: str) -> tuple[str, ...]:
    """The families of a font split: ``"train"``, ``"held_out"`` or ``"shifted"`` (``"all"``: train and
    held out; ``"train_more"``: the training families and ``MORE_TRAIN_FAMILIES``)."""
    families = {
        "train": TRAIN_FAMILIES,
        "train_more": TRAIN_FAMILIES + MORE_TRAIN_FAMILIES,
        "held_out": HELD_OUT_FAMILIES,
        "all": TRAIN_FAMILIES + HELD_OUT_FAMILIES,
        "shifted": SHIFTED_FAMILIES,
    }.get(split)
    if families is None:
        raise ValueError(f"unknown font split {split!r}; use {', '.join(repr(s) for s in FONT_SPLITS)}")
    return tuple(families)


def font_split(text_split: str, held_out: bool = False, more_fonts: bool = False, regime: str = "standard") -> str:
    """Which font split a synthetic set draws from: the held-out families when asked, all families for
    validation, the training ones (with ``MORE_TRAIN_FAMILIES`` on request) for training; the shifted
    regime has its own."""
    if regime == "shifted":
        return "shifted"
    if held_out:
        return "held_out"
    if text_split == "val":
        return "all"
    return "train_more" if more_fonts else "train"


def faces_for(split: str) -> tuple[FontFace, ...]:
    """Faces of a font split (``families_of``), in ``FACES`` order."""
    families = families_of(split)
    return tuple(f for f in FACES if f.family in families)


def face_by_name(name: str) -> FontFace:
    """Look a face up by ``FontFace.name`` (e.g. ``"DejaVu Serif Bold"``)."""
    for face in FACES:
        if face.name == name:
            return face
    raise ValueError(f"unknown font {name!r}; known: {', '.join(f.name for f in FACES)}")

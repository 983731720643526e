"""Recognition restricted to the characters of the configured language.

rapidocr's recogniser is multilingual (its CTC head has one class per character of many
scripts) and, with nothing to tell it the page is English, a faint ``a`` wins as ``ą`` and an
``l`` as ``ł``. ``MaskedCtcDecode`` replaces rapidocr's CTC decoder: every class outside the
language's alphabet (and the CTC blank) is masked before the argmax, so the best *allowed*
character wins. Where that masked read and the unmasked read folded to ASCII (``ą`` -> ``a``)
differ in a word, the one that is a dictionary word is kept.

Each line's score is the mean of its characters' probabilities as rapidocr reports it; the
decoder also keeps every character's probability (``CharScores.chars``), which the line's
calibrated confidence uses.
"""

from __future__ import annotations

import string
import unicodedata
from collections.abc import Callable
from typing import Any

import numpy as np

LANGUAGES: dict[str, str] = {"en": string.printable.strip() + " "}  # language -> its alphabet
"""The alphabet of each language a page may be configured as (``Settings.ocr_language``)."""


class CharScores(float):
    """A line's mean character probability (what rapidocr reports), carrying each character's."""

    chars: tuple[float, ...]

    def __new__(cls, chars: list[float]) -> CharScores:
        value = super().__new__(cls, round(float(np.mean(chars)), 5) if chars else 0.0)
        value.chars = tuple(chars)
        return value


_NO_DECOMPOSITION = str.maketrans({"ł": "l", "Ł": "L", "ħ": "h", "Ħ": "H", "ı": "i", "ø": "o", "Ø": "O", "đ": "d",
                                   "Đ": "D", "ß": "ss", "æ": "ae", "Æ": "AE", "œ": "oe", "Œ": "OE"})


def ascii_fold(text: str) -> str:
    """Accents and ligatures taken off (``ą`` -> ``a``, ``ł`` -> ``l``, ``ﬁ`` -> ``fi``); what has no ASCII form dropped."""
    return unicodedata.normalize("NFKD", text.translate(_NO_DECOMPOSITION)).encode("ascii", "ignore").decode("ascii")


def allowed_classes(character: list[str], alphabet: str) -> np.ndarray:
    """Boolean mask over a CTC head's classes: the blank (class 0) and the alphabet's characters."""
    allowed = np.array([c in alphabet for c in character], dtype=bool)
    allowed[0] = True
    return allowed


def _collapse(indices: np.ndarray, probs: np.ndarray, character: list[str]) -> tuple[str, list[float]]:
    """Greedy CTC: repeats merged, blanks dropped."""
    keep = np.ones(len(indices), dtype=bool)
    keep[1:] = indices[1:] != indices[:-1]
    keep &= indices != 0
    return "".join(character[i] for i in indices[keep]), [round(float(p), 5) for p in probs[keep]]


def prefer_words(masked: str, folded: str, known: Callable[[str], bool]) -> str:
    """Word by word, the masked read unless only the folded one is a dictionary word."""
    a, b = masked.split(" "), folded.split(" ")
    if len(a) != len(b):
        return masked
    return " ".join(y if x != y and y.isalpha() and known(y) and not known(x) else x for x, y in zip(a, b))


def masked_decoder(base: type, character: list[str], alphabet: str, known: Callable[[str], bool] | None) -> Any:
    """An instance of a subclass of rapidocr's ``CTCLabelDecode`` (passed as ``base``, so this
    module needs no rapidocr import) that decodes within ``alphabet``."""

    class MaskedCtcDecode(base):  # a base class found at run time (rapidocr ships no types)
        def __init__(self) -> None:
            super().__init__(character=list(character[1:-1]))  # rapidocr puts the blank and space back
            self.kept = np.flatnonzero(allowed_classes(self.character, alphabet))
            self.known = known

        def __call__(self, preds: np.ndarray, return_word_box: bool = False, **kwargs: Any) -> tuple[list, list]:
            # the allowed classes' columns only: a copy of a hundred columns, not of all the model's
            kept = preds[:, :, self.kept]
            best = kept.argmax(axis=2)
            indices, probs = self.kept[best], np.take_along_axis(kept, best[..., None], axis=2)[..., 0]
            free = preds.argmax(axis=2)
            lines = []
            for row in range(len(indices)):
                text, chars = _collapse(indices[row], probs[row], self.character)
                if self.known is not None and not np.array_equal(free[row], indices[row]):
                    folded = ascii_fold(_collapse(free[row], probs[row], self.character)[0])
                    text = prefer_words(text, folded, self.known)
                lines.append((text, CharScores(chars)))
            if not return_word_box:
                return lines, []
            return lines, super().__call__(preds, return_word_box, **kwargs)[1]

    return MaskedCtcDecode()


def restrict_engine(engine: Any, language: str, known: Callable[[str], bool] | None) -> None:
    """Make a loaded rapidocr engine decode within ``language``'s alphabet."""
    from rapidocr.ch_ppocr_rec.utils import CTCLabelDecode  # the engine that calls this has rapidocr

    recogniser = engine._load_rec_model()
    current = recogniser.postprocess_op
    recogniser.postprocess_op = masked_decoder(CTCLabelDecode, list(current.character), LANGUAGES[language], known)

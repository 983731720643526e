"""Recognition within the page's language: rapidocr's CTC decoder masked to the alphabet."""

from __future__ import annotations

import numpy as np
import pytest
from rapidocr.ch_ppocr_rec.utils import CTCLabelDecode

from darkread.cloud.ocr.charset import LANGUAGES, CharScores, allowed_classes, ascii_fold, masked_decoder, prefer_words

CHARACTERS = ["a", "ą", "b", "ł", "l"]  # a stand-in for the model's 18,710 classes; rapidocr adds blank and space


def preds(frames: list[dict[str, float]], decoder: CTCLabelDecode) -> np.ndarray:
    """One line's class probabilities, each frame a few classes' probabilities (the rest share what is left)."""
    out = np.full((1, len(frames), len(decoder.character)), 1e-4, dtype=np.float32)
    for t, frame in enumerate(frames):
        for ch, p in frame.items():
            out[0, t, decoder.character.index(ch)] = p
    return out


def test_only_the_blank_and_the_alphabet_survive_the_mask() -> None:
    mask = allowed_classes(["blank", "a", "ą", "ł", "Z", "!", " "], LANGUAGES["en"])
    assert mask.tolist() == [True, True, False, False, True, True, True]


def test_a_faint_letter_read_as_a_foreign_one_becomes_the_best_english_one() -> None:
    decoder = masked_decoder(CTCLabelDecode, ["blank", *CHARACTERS, " "], LANGUAGES["en"], known=None)
    # "ąb": the model's first choice in frame 0 is ą, its best English one a
    lines, _ = decoder(preds([{"ą": 0.6, "a": 0.3}, {"blank": 0.9}, {"b": 0.95}], decoder))
    (text, score), = lines
    assert text == "ab"
    assert isinstance(score, CharScores) and score.chars == pytest.approx((0.3, 0.95), abs=1e-4)
    assert float(score) == pytest.approx(0.625, abs=1e-4)


def test_the_ascii_fold_wins_where_only_it_is_a_dictionary_word() -> None:
    words = {"all"}
    decoder = masked_decoder(CTCLabelDecode, ["blank", *CHARACTERS, " "], LANGUAGES["en"], known=words.__contains__)
    # frames: ą (a 2nd), ł (b 2nd), blank, l: masked "abl", folded "all" -> the dictionary word
    lines, _ = decoder(preds([{"ą": 0.7, "a": 0.2}, {"ł": 0.6, "b": 0.3}, {"blank": 0.9}, {"l": 0.9}], decoder))
    assert lines[0][0] == "all"


def test_prefer_words_keeps_the_masked_read_unless_only_the_fold_is_a_word() -> None:
    known = {"fox", "the"}.__contains__
    assert prefer_words("tho fox", "the fox", known) == "the fox"
    assert prefer_words("the fox", "tho fox", known) == "the fox"
    assert prefer_words("the fox", "the fox jumps", known) == "the fox"  # different word counts: masked
    assert ascii_fold("ąłħãı ﬁ") == "alhai fi"


def test_the_engine_reads_within_the_language(tmp_path: object) -> None:
    from darkread.cloud.ocr.rapid import RapidOcrBackend

    with pytest.raises(ValueError, match="no alphabet"):
        RapidOcrBackend(language="xx")

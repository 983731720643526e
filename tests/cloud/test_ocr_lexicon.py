from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("symspellpy")

from darkread.cloud.ocr import create_backend
from darkread.cloud.ocr.base import OcrLine, OcrResult
from darkread.cloud.ocr.lexicon import LexiconCorrected, LexiconCorrector
from darkread.cloud.settings import Settings
from darkread.core.text_metrics import error_rates


@pytest.fixture(scope="module")
def corrector() -> LexiconCorrector:
    return LexiconCorrector()


def test_candidates_differ_in_lookalike_glyphs_only() -> None:
    from darkread.cloud.ocr.lexicon import misreadings

    def reachable(read: str) -> set[str]:
        return {w for k in range(4) for w in misreadings(read, k)}

    assert "are" in reachable("aro") and "busiest" in reachable("buslest")
    assert "first" in reachable("frst")  # a lost i stem
    assert "hardiest" not in reachable("tardiest")  # t and h do not look alike
    assert "secretaries" not in reachable("sectaries")  # two letters more is not a misreading
    assert "cats" not in reachable("cat")


def test_misread_prose_is_corrected_in_its_case_and_punctuation(corrector: LexiconCorrector) -> None:
    reference = "not untrue that many\nsectaries and false teachers\nare then busiest in\nseducing; but yet more true"
    read = "not untrue that many\nsectaries and folse teachers\naro then buslest In\nseducing; but yet more true"
    corrected = corrector.correct(read)
    assert corrected == reference
    assert error_rates(reference, read).cer > 0.03 and error_rates(reference, corrected).cer == 0.0
    assert corrector.correct("should be Oxtirpato, and") == "should be Extirpate, and"
    assert corrector.correct("the outhor's name, or at least") == "the author's name, or at least"
    assert corrector.correct("rollglons and civil\nsupremacies, so Itsalf") == "religions and civil\nsupremacies, so itself"
    assert corrector.correct("foundere of our true\nformal and slavieh, as ye") == "founders of our true\nformal and slavish, as ye"
    # most words misread: still prose when each is one lookalike glyph from a word (i without dots)
    assert corrector.correct("Slxty zlppers were qulckly") == "Sixty zippers were quickly"


def test_real_words_misread_for_others_are_judged_by_their_neighbours(corrector: LexiconCorrector) -> None:
    assert corrector.correct("will toll us more at large.") == "will tell us more at large."
    assert corrector.correct("unless tho printer's and the") == "unless the printer's and the"
    for line in ("pay the toll of the bridge", "far more than that", "the quick fox"):
        assert corrector.correct(line) == line


def test_misreadings_swap_only_lookalike_glyphs() -> None:
    from darkread.cloud.ocr.lexicon import misreadings

    one = set(misreadings("aro", 1))
    assert "are" in one and "arc" in one and "aro" not in one and "bro" not in one
    assert "first" in set(misreadings("frst", 0))  # a lost stem put back
    assert "religions" in set(misreadings("rollglons", 3)) and "religions" not in set(misreadings("rollglons", 2))


def test_words_read_right_stay_as_they_are(corrector: LexiconCorrector) -> None:
    clean = [
        "among the tardiest, and the sectaries of Italy,",  # rare words and names
        "In the beginning. It was",  # sentence starts keep their capitals
        "the quick brown fox jumps over the lazy dog.",
    ]
    for line in clean:
        assert corrector.correct(line) == line


def test_random_letters_and_codes_are_not_prose(corrector: LexiconCorrector) -> None:
    for line in ("qXvb Lkmt zrpw hh", "A7-33 kq9 zx", "fOOLza Wt vbbq"):
        assert corrector.correct_line(line) == line


class _Engine:
    name = "engine"

    def __init__(self, text: str) -> None:
        self.text = text
        self.closed = False

    def ready(self) -> bool:
        return True

    def read(self, image: np.ndarray) -> OcrResult:
        lines = [OcrLine(t, (0, 10 * k, 50, 10 * k + 8), 0.9) for k, t in enumerate(self.text.split("\n"))]
        return OcrResult(self.text, lines)

    def close(self) -> None:
        self.closed = True


def test_wrapper_corrects_text_and_lines_and_keeps_the_engine_reachable() -> None:
    engine = _Engine("tell us voinly of new\nopinions, whon this very")
    wrapped = LexiconCorrected(engine)
    result = wrapped.read(np.full((20, 20), 255, np.uint8))
    assert result.text == "tell us vainly of new\nopinions, when this very"
    assert [line.text for line in result.lines] == result.text.split("\n")
    assert result.lines[1].box == (0, 10, 50, 18) and result.lines[1].confidence == 0.9
    assert wrapped.ready() and wrapped.name == "engine+lexicon"
    wrapped.close()
    assert engine.closed


def test_settings_switch_the_correction() -> None:
    on = create_backend(Settings(_env_file=None, ocr_backend="tesseract"))
    off = create_backend(Settings(_env_file=None, ocr_backend="tesseract", ocr_lexicon=False))
    assert isinstance(on, LexiconCorrected) and not isinstance(off, LexiconCorrected)


def test_the_kind_of_text_decides_how_much_is_corrected(corrector: LexiconCorrector) -> None:
    assert corrector.text_kind("sona dop Xq7 bL\nkw;rt Zp ao") == "letters"
    assert corrector.text_kind("tamed lantern orchard\nvelvet margin quarry") == "words"
    assert corrector.text_kind("will tell us more at large\nand the rest of it") == "text"
    # random letters: no correction at all (the word-list pass made "sona dop" "sana dep")
    assert corrector.correct("sona dop Xq7 bL") == "sona dop Xq7 bL"
    # a word list: real words are never swapped for others, non-words are fixed
    assert corrector.correct("tamed lantern orchard\nvelvet margln quarry") == "tamed lantern orchard\nvelvet margin quarry"


def misreadings_of(read: str, substitutions: int) -> set[str]:
    from darkread.cloud.ocr.lexicon import misreadings

    return set(misreadings(read, substitutions))


def test_a_filled_in_s_is_read_back_from_o_and_a(corrector: LexiconCorrector) -> None:
    # a small s whose spine the reconstruction filled in reads as o or a (a word list: non-words fixed alone)
    assert corrector.correct("come meaneat Brook cowardice\nshow would indifferent") == (
        "come meanest Brook cowardice\nshow would indifferent")
    assert corrector.correct("deoorveo errors under\nreasons battle compelled may") == (
        "deserves errors under\nreasons battle compelled may")
    assert {"cats", "cast"} <= misreadings_of("cato", 1) | misreadings_of("caot", 1)


def test_s_and_c_stay_apart() -> None:
    assert "prose" not in misreadings_of("proce", 1) and "prose" in misreadings_of("proee", 1)


def test_one_edit_reaches_every_single_letter_change() -> None:
    from string import ascii_lowercase

    from darkread.cloud.ocr.lexicon import one_edit

    assert {"acceptance", "accptnnce", "acecptnnce", "acceptnnces"} <= one_edit("acceptnnce")
    expected = {"a", "b", "ba"} | {x + "b" for x in ascii_lowercase} | {"a" + x for x in ascii_lowercase}
    expected |= {x + "ab" for x in ascii_lowercase} | {"a" + x + "b" for x in ascii_lowercase} | {"ab" + x for x in ascii_lowercase}
    assert one_edit("ab") == expected - {"ab"}


def test_coherent_text_fixes_long_non_words_one_letter_off(corrector: LexiconCorrector) -> None:
    # a glyph misread beyond the lookalikes (c for d, r for a): the language model picks the word
    assert corrector.correct("do so much abound and true\nknowlecge is kept at") == "do so much abound and true\nknowledge is kept at"
    assert corrector.correct("to his last testrment who") == "to his last testament who"
    # short non-words have too many neighbours one letter away: left to the lookalikes
    assert corrector.correct("where and out of what prace") == "where and out of what prace"


def test_clean_prose_is_left_almost_untouched() -> None:
    from darkread.lab.eval.clean_text import clean_text_check

    check = clean_text_check()
    assert check.lines > 400
    assert check.changed_share < 0.02 and check.cer_added < 0.001


def test_a_token_longer_than_any_word_is_left_as_read_without_a_search(corrector: LexiconCorrector) -> None:
    # a band of noise read as one long token: no fix can reach a word, and the search would take minutes
    noise = "knowlecge" * 200
    page = f"and the rest of it is {noise} and the end of it\nsome more words about {noise} in it"
    assert corrector.correct(page) == page
    assert corrector.correct(f"tamed lantern {noise}\nvelvet margln quarry") == f"tamed lantern {noise}\nvelvet margin quarry"


def test_two_letter_non_words_in_prose_are_weighed_by_the_language_model(corrector: LexiconCorrector) -> None:
    # "be" whose e closed into an o; a word of two letters gets lookalikes only, never a lost stem
    assert corrector.correct("earth, so Truth bo in the\nwinds of doctrine") == "earth, so Truth be in the\nwinds of doctrine"
    assert corrector.correct("What would ye do then?\nshould ye suppress all this") == (
        "What would ye do then?\nshould ye suppress all this")
    # a word list has no context to choose by: left as read
    assert corrector.correct("tares soon bo kingdom\nhidden stratagems manage") == "tares soon bo kingdom\nhidden stratagems manage"


def test_a_period_before_a_lower_case_word_is_read_as_a_comma() -> None:
    from darkread.cloud.ocr.lexicon import comma_before_lowercase

    assert comma_before_lowercase("opinion of theirs. that none\nlike. is the worst and") == (
        "opinion of theirs, that none\nlike, is the worst and")
    assert comma_before_lowercase("hath puffed up.\nthe rest") == "hath puffed up,\nthe rest"
    # a sentence's end, an abbreviation, a number or an initial stay
    kept = "the end. The next\nsay etc. and so on\nsee p. 12 and J. doe\nat 3. then"
    assert comma_before_lowercase(kept) == kept


def test_only_prose_gets_its_periods_read_as_commas(corrector: LexiconCorrector) -> None:
    assert corrector.correct("opinion of theirs. that none\nmust be thought") == "opinion of theirs, that none\nmust be thought"
    letters = "Xq7. abT kL9 zz. qr\nWv3. mnP q"
    assert corrector.correct(letters) == letters


def test_a_capital_i_read_as_a_one_or_an_l_is_weighed_by_the_language_model(corrector: LexiconCorrector) -> None:
    # a sans-serif I is a bare stroke: the engine reads it as 1 or l
    assert corrector.correct("petty schisms. Not that 1\ncan think well of every") == (
        "petty schisms. Not that I\ncan think well of every")
    assert corrector.correct("so l think that we should\ngo home now and rest") == "so I think that we should\ngo home now and rest"
    # a number in prose stays one
    for numbers in ("see page 1 of the report\nand the rest of it here", "there were 1 or 2 of them\nin the house that day",
                    "add 1 cup of sugar to the\nbowl and stir it well"):
        assert corrector.correct(numbers) == numbers

from __future__ import annotations

import pytest

from darkread.core.text_metrics import error_rates, normalize_text


def test_normalisation_collapses_whitespace_and_line_breaks() -> None:
    assert normalize_text("  two\nlines \t here ") == "two lines here"


def test_identical_text_scores_zero_even_with_other_line_breaks() -> None:
    rates = error_rates("No covered work\nshall be", "No covered work shall be")
    assert rates.cer == 0.0 and rates.wer == 0.0


def test_known_edit_counts() -> None:
    rates = error_rates("abcd efgh", "abXd efgh")  # one substitution in 9 characters, 1 of 2 words
    assert rates.cer == pytest.approx(1 / 9)
    assert rates.wer == pytest.approx(1 / 2)


def test_case_and_punctuation_count() -> None:
    assert error_rates("Law.", "law").cer == pytest.approx(2 / 4)


@pytest.mark.parametrize(("hyp", "expected"), [("", 0.0), ("anything", 1.0)])
def test_empty_reference_is_guarded(hyp: str, expected: float) -> None:
    assert error_rates("", hyp).cer == expected


def test_empty_hypothesis_is_total_loss() -> None:
    rates = error_rates("some text", "")
    assert rates.cer == 1.0 and rates.wer == 1.0

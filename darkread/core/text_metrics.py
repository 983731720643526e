"""Character and word error rates with one stated normalisation.

Normalisation (both sides): Unicode NFKC, every run of whitespace (including line breaks) collapsed
to one space, leading/trailing space stripped. Case and punctuation count, as in the paper's
figures. An empty reference has no defined rate: it scores 0.0 against an empty hypothesis and
1.0 against anything else (jiwer itself is inconsistent there).
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass

import jiwer

_WHITESPACE = re.compile(r"\s+")


def normalize_text(text: str) -> str:
    return _WHITESPACE.sub(" ", unicodedata.normalize("NFKC", text)).strip()


@dataclass(frozen=True)
class ErrorRates:
    cer: float
    wer: float
    reference_chars: int
    reference_words: int


def error_rates(reference: str, hypothesis: str) -> ErrorRates:
    ref, hyp = normalize_text(reference), normalize_text(hypothesis)
    if not ref:
        miss = 0.0 if not hyp else 1.0
        return ErrorRates(cer=miss, wer=miss, reference_chars=0, reference_words=0)
    if not hyp:
        return ErrorRates(cer=1.0, wer=1.0, reference_chars=len(ref), reference_words=len(ref.split()))
    return ErrorRates(
        cer=float(jiwer.cer(ref, hyp)),
        wer=float(jiwer.wer(ref, hyp)),
        reference_chars=len(ref),
        reference_words=len(ref.split()),
    )

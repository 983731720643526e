"""A noisy-channel pass over coherent text: each lower-case word may be the one printed or a
lookalike of it, and a trigram language model picks the likeliest sequence (Viterbi over the line).

The channel: keeping a word costs nothing; replacing a non-word (not in the word list) by a
dictionary word costs ``fix_log_prob`` per lookalike glyph, or ``edit_log_prob`` for a long
non-word one letter from the word beyond the lookalikes; replacing a real word by another
costs ``swap_log_prob`` per glyph, far more, so a read word is only swapped when the words
around it make the other much likelier ("will toll us" -> "will tell us"). Capitalised words
(names, sentence starts) and words with digits are never replaced; they still count as context.
Words the model does not know score ``unknown_log_prob``.

The model is pocketsphinx's US-English trigram LM (``en-us.lm.bin``, read with its ``NGramModel``;
a tenth of a second to load). ``pocketsphinx`` is part of the ``cloud`` extra for it.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from ..errors import OcrUnavailableError

LOG_BASE = math.log(1.0001)  # sphinx log-probabilities are in base 1.0001
MODELS: dict[str, tuple[str, str]] = {"en": ("en-us", "en-us.lm.bin")}  # language -> (folder, file) in pocketsphinx's models
SENTENCE_START = "<s>"


@lru_cache(maxsize=2)
def load_model(language: str) -> Any:
    """The language's trigram model (once per process)."""
    if language not in MODELS:
        raise OcrUnavailableError(f"no language model for {language!r}", backend="lexicon")
    try:
        from pocketsphinx import NGramModel, get_model_path
    except ImportError as exc:
        raise OcrUnavailableError("the language model needs pocketsphinx (pip install pocketsphinx)", backend="lexicon") from exc
    folder, name = MODELS[language]
    path = os.path.join(get_model_path(), folder, name)
    if not os.path.isfile(path):
        raise OcrUnavailableError(f"the language model {path} is missing", backend="lexicon")
    return NGramModel.readfile(path)


@dataclass(frozen=True)
class Candidate:
    word: str  # lower case
    channel: float  # log-probability that ``word`` was printed and read as the token


@dataclass
class TrigramScorer:
    """log P(word | two before) from the model, natural log, unknown words at a floor."""

    model: Any
    unknown_log_prob: float = math.log(1e-8)

    def __post_init__(self) -> None:
        self._cache: dict[tuple[str, ...], float] = {}

    def log_prob(self, word: str, history: tuple[str, str]) -> float:
        key = (word, history[1], history[0])  # the model wants the word, then its history newest first
        found = self._cache.get(key)
        if found is None:
            raw = self.model.prob([w for w in key if w])
            found = self.unknown_log_prob if raw <= -(2**28) else max(raw * LOG_BASE, self.unknown_log_prob)
            self._cache[key] = found
        return found


def viterbi(slots: Sequence[Sequence[Candidate]], score: Callable[[str, tuple[str, str]], float]) -> list[str]:
    """The likeliest word of each slot under the channel costs and the trigram model.

    A slot with one candidate is fixed. State: the last two words chosen."""
    if not slots:
        return []
    start = ("", SENTENCE_START)
    best: dict[tuple[str, str], tuple[float, list[str]]] = {start: (0.0, [])}
    for slot in slots:
        step: dict[tuple[str, str], tuple[float, list[str]]] = {}
        for (older, newer), (total, path) in best.items():
            for cand in slot:
                value = total + cand.channel + score(cand.word, (older, newer))
                state = (newer, cand.word)
                if state not in step or value > step[state][0]:
                    step[state] = (value, [*path, cand.word])
        best = step
    return max(best.values(), key=lambda item: item[0])[1]

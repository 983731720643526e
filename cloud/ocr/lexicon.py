"""Dictionary correction of an offline engine's text: the language prior an LLM reader has built in.

Reconstructed strokes at 6-10 px x-height confuse a few glyph pairs (e/o, i/l, a/o, c/e, s/e); an
engine without a language model reports them as read ("aro then buslest"), where GPT-4o would
read "are then busiest". The correction is deliberately conservative, because a general spelling
corrector "fixes" rare words that were read right (tardiest -> hardiest):

* only lines that read as language are touched: at least ``min_known_fraction`` of their words
  must already be dictionary words or one lookalike glyph from one (words of two letters or more; random letters,
  codes and part numbers stay as read);
* only alphabetic words of at least ``min_length`` letters that are *not* in the dictionary are
  replaced, and only by a dictionary word that differs from them in lookalike glyphs alone
  (``CONFUSABLE``; at most 1, 2 or 3 of them for words of up to 4, 7 or more letters), or by one
  lost ``i``/``l``/``t`` stem; fewest changes first, then the most frequent word; words with no
  such candidate stay as read;
* a capital I inside a sentence ("busiest In seducing", "so Itsalf") is read as i when the word
  is short or not a dictionary word (longer known ones may be names: Italy, Ionia);
* a misreading can also be a real word ("will toll us", "unless tho printer's"): a lower-case word
  is swapped for a lookalike one only when it forms no known word pair with its neighbours, the
  lookalike does, and that pair outweighs the odds of a glyph swap (``swap_probability``);
* capitalisation (lower, Capitalised, UPPER) and surrounding punctuation are kept.

The word and word-pair lists are SymSpell's English frequency dictionaries (82,765 words, 242,342
pairs; MIT licence), shipped inside the ``symspellpy`` package; no network is needed. On clean
prose from the corpus 1 % of 28-character lines gain a one-letter change (archaic words: ere ->
are, lest -> lost), while it removes a third to a half of the errors on reconstructed pages.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from functools import lru_cache
from itertools import combinations, product
from typing import TYPE_CHECKING

import numpy as np

from ..errors import OcrUnavailableError
from .base import OcrResult

if TYPE_CHECKING:
    from symspellpy import SymSpell

    from .base import OcrBackend

logger = logging.getLogger(__name__)

_TOKEN = re.compile(r"^(?P<lead>[^A-Za-z]*)(?P<word>[A-Za-z]+)(?P<trail>(?:'[A-Za-z]{1,2})?[^A-Za-z]*)$")  # author's
# (s and e: small closed glyphs a dim reconstruction fills in alike, "foundere of our true",
# "formal and slavieh"; what the group gains and costs: cloud/README.md, OCR engines)
_CONFUSABLE_GROUPS = ("eoac", "ilt", "nu", "hb", "rt", "vy", "se")
CONFUSABLE: frozenset[tuple[str, str]] = frozenset(
    (a, b) for group in _CONFUSABLE_GROUPS for a in group for b in group if a != b
)
_ALTERNATIVES: dict[str, str] = {
    ch: "".join(sorted({b for a, b in CONFUSABLE if a == ch})) for ch in {a for a, _ in CONFUSABLE}
}
DROPPED_STEMS = "ilt"  # thin strokes a reconstruction can lose entirely
_SENTENCE_END = (".", "!", "?", ":", ";")
_CORE = re.compile(r"[A-Za-z]+")


def misreadings(read: str, substitutions: int) -> Iterator[str]:
    """Words ``read`` (lower case) may be a misreading of with exactly ``substitutions`` lookalike
    glyphs swapped; with 0, the words it becomes when one lost thin stem is put back."""
    if substitutions == 0:
        for k in range(1, len(read) + 1):
            for stem in DROPPED_STEMS:
                yield read[:k] + stem + read[k:]
        return
    positions = [k for k, ch in enumerate(read) if ch in _ALTERNATIVES]
    for chosen in combinations(positions, substitutions):
        for letters in product(*(_ALTERNATIVES[read[k]] for k in chosen)):
            word = list(read)
            for k, ch in zip(chosen, letters):
                word[k] = ch
            yield "".join(word)


@lru_cache(maxsize=1)
def _dictionary() -> SymSpell:
    """SymSpell's bundled English word and word-pair counts (about 2 s, once per process); its
    spelling search is not used (lookalike glyphs decide the candidates), so no edit index is built."""
    try:
        from importlib.resources import files

        from symspellpy import SymSpell
    except ImportError as exc:
        raise OcrUnavailableError(
            "dictionary correction needs symspellpy (pip install symspellpy)", backend="lexicon"
        ) from exc
    speller = SymSpell(max_dictionary_edit_distance=0, prefix_length=7)
    path = files("symspellpy") / "frequency_dictionary_en_82_765.txt"
    if not speller.load_dictionary(str(path), term_index=0, count_index=1):
        raise OcrUnavailableError(f"could not load the word list {path}", backend="lexicon")
    bigrams = files("symspellpy") / "frequency_bigramdictionary_en_243_342.txt"
    if not speller.load_bigram_dictionary(str(bigrams), term_index=0, count_index=2):
        raise OcrUnavailableError(f"could not load the word-pair list {bigrams}", backend="lexicon")
    return speller


def _with_case_of(template: str, word: str) -> str:
    if template.isupper() and len(template) > 1:
        return word.upper()
    if template[:1].isupper():
        return word[:1].upper() + word[1:]
    return word


@dataclass
class LexiconCorrector:
    """Corrects the misread words of prose lines: unknown ones by lookalike glyphs, known ones by
    their neighbours (see the module docstring)."""

    max_substitutions: int = 3
    min_length: int = 3
    min_known_fraction: float = 0.3
    swap_probability: float = 1e-4  # prior of one lookalike-glyph swap, against the context's evidence
    _speller: SymSpell | None = field(default=None, init=False, repr=False)
    _total: float = field(default=0.0, init=False, repr=False)

    def _words(self) -> SymSpell:
        if self._speller is None:
            self._speller = _dictionary()
        return self._speller

    def known(self, word: str) -> bool:
        return word.lower() in self._words().words

    def correct_word(self, word: str, *, in_sentence: bool = False) -> str:
        """The most frequent dictionary word ``word`` may be a misreading of, in its case; else ``word``."""
        i_read_as_capital = in_sentence and len(word) > 1 and word[0] == "I" and word[1:].islower()
        if i_read_as_capital and len(word) <= 3 and self.known("i" + word[1:]):
            return "i" + word[1:]  # "In", "It", "Is" inside a sentence
        if len(word) < self.min_length or self.known(word):
            return word  # longer known words with a capital may be names: Italy, Ionia
        if i_read_as_capital:  # an unknown word: its capital I may be a misread i ("so Itsalf")
            lowered = "i" + word[1:]
            corrected = self._closest(lowered)
            return corrected if corrected != lowered else word  # no such word: perhaps a name (Irenaeus)
        return self._closest(word)

    def _one_glyph_from_known(self, word: str) -> bool:
        """Whether swapping one lookalike glyph of ``word`` (alphabetic, at least ``min_length``) makes a dictionary word."""
        if len(word) < self.min_length or not word.isalpha():
            return False
        counts = self._words().words
        return any(w in counts for w in misreadings(word.lower(), 1))

    def _closest(self, word: str) -> str:
        """The most frequent dictionary word the unknown ``word`` may be a misreading of, or ``word``."""
        read = word.lower()
        counts = self._words().words
        most = 1 if len(read) <= 4 else (2 if len(read) <= 7 else self.max_substitutions)
        for level in [1, 0, *range(2, most + 1)]:  # one swap, one lost stem, then more swaps
            if level > most:
                continue
            found = {w for w in misreadings(read, level) if w in counts}
            if found:
                return _with_case_of(word, max(sorted(found), key=counts.__getitem__))
        return word

    def correct_line(self, line: str, *, after_sentence_end: bool = True) -> str:
        """``after_sentence_end``: whether the text before this line ended a sentence (or there is none)."""
        return self._correct_line(line, after_sentence_end)[0]

    def _correct_line(self, line: str, after_sentence_end: bool) -> tuple[str, bool]:
        """The line with its unknown words corrected, and whether it reads as prose."""
        tokens = line.split(" ")
        parsed = [_TOKEN.match(t) for t in tokens]
        words = [m.group("word") for m in parsed if m is not None and len(m.group("word")) > 1]
        if not words:
            return line, False
        # (a word one lookalike glyph from a dictionary word counts: "Slxty zlppers were qulckly"
        # is prose whose i lost their dots)
        known = sum(self.known(w) or self._one_glyph_from_known(w) for w in words) / len(words)
        if known < self.min_known_fraction:
            return line, False  # not prose: leave letters, codes and numbers as read
        out = []
        sentence_start = after_sentence_end
        for token, match in zip(tokens, parsed):
            if match is None:
                out.append(token)
            else:
                in_sentence = not sentence_start and not match.group("lead")
                out.append(match.group("lead") + self.correct_word(match.group("word"), in_sentence=in_sentence)
                           + match.group("trail"))
            sentence_start = token.endswith(_SENTENCE_END) if token else sentence_start
        return " ".join(out), True

    def correct(self, text: str) -> str:
        lines: list[str] = []
        prose: list[bool] = []
        ended = True
        for line in text.split("\n"):
            corrected, is_prose = self._correct_line(line, ended)
            lines.append(corrected)
            prose.append(is_prose)
            if line.strip():
                ended = line.rstrip().endswith(_SENTENCE_END)
        return "\n".join(self._in_context(lines, prose))

    # -- known words that are likely misreadings in their context ("will toll us", "tho printer") --

    def _context_score(self, word: str, before: str | None, after: str | None) -> float:
        """log of a stupid-backoff bigram score of ``word`` between its neighbours."""
        speller = self._words()
        counts, pairs = speller.words, speller.bigrams
        if not self._total:
            self._total = float(sum(counts.values()))
        own = max(counts.get(word, 0), 1)
        score = 0.0
        if before is not None and before in counts:
            pair = pairs.get(f"{before} {word}")
            score += math.log(pair / counts[before] if pair else 0.4 * own / self._total)
        else:
            score += math.log(own / self._total)
        if after is not None and after in counts:
            pair = pairs.get(f"{word} {after}")
            score += math.log(pair / own if pair else 0.4 * counts[after] / self._total)
        return score

    def _in_a_pair(self, word: str, before: str | None, after: str | None) -> bool:
        pairs = self._words().bigrams
        return (before is not None and f"{before} {word}" in pairs) or (after is not None and f"{word} {after}" in pairs)

    def _in_context(self, lines: list[str], prose: list[bool]) -> list[str]:
        """Swap a lower-case known word for a lookalike one when it forms no known word pair with its
        neighbours, the lookalike does, and the pair makes it far likelier (by more than the odds of
        a glyph swap). Capitalised words (names, sentence starts) and lines that are not prose stay
        as they are."""
        tokens = [(k, t) for k, line in enumerate(lines) for t in line.split(" ")]
        cores = []
        for _, token in tokens:
            found = _CORE.search(token)
            cores.append(found.group(0).lower() if found else None)
        counts = self._words().words
        log_swap = math.log(self.swap_probability)
        out = [token for _, token in tokens]
        for i, (k, token) in enumerate(tokens):
            match = _TOKEN.match(token)
            if not prose[k] or match is None or not match.group("word").islower():
                continue
            word = match.group("word")
            candidates = sorted({c for c in misreadings(word, 1) if c in counts})
            if not candidates:
                continue
            before = cores[i - 1] if i > 0 else None
            after = cores[i + 1] if i + 1 < len(cores) else None
            if self._in_a_pair(word, before, after):
                continue  # the words around it know this word: keep it
            best = max(candidates, key=lambda c: self._context_score(c, before, after))
            if not self._in_a_pair(best, before, after):
                continue  # no evidence beyond word frequency, which would flatten rare words
            if self._context_score(best, before, after) + log_swap > self._context_score(word, before, after):
                out[i] = match.group("lead") + best + match.group("trail")
                cores[i] = best
        joined: list[list[str]] = [[] for _ in lines]
        for (k, _), token in zip(tokens, out):
            joined[k].append(token)
        return [" ".join(parts) for parts in joined]


class LexiconCorrected:
    """An engine whose text goes through ``LexiconCorrector`` (line boxes and confidences kept)."""

    def __init__(self, engine: OcrBackend, corrector: LexiconCorrector | None = None) -> None:
        self.engine = engine
        self.corrector = corrector or LexiconCorrector()
        self.name = f"{engine.name}+lexicon"

    def __getattr__(self, attribute: str) -> object:  # close(), timeouts, ... of the wrapped engine
        if attribute == "engine":
            raise AttributeError(attribute)
        return getattr(self.engine, attribute)

    def ready(self) -> bool:
        if not self.engine.ready():
            return False
        try:
            self.corrector.known("the")
        except OcrUnavailableError as exc:
            logger.warning("%s", exc)
            return False
        return True

    def read(self, image: np.ndarray) -> OcrResult:
        result = self.engine.read(image)
        text = self.corrector.correct(result.text)
        corrected = dict(zip(result.text.split("\n"), text.split("\n")))
        lines = [replace(line, text=corrected.get(line.text, line.text)) for line in result.lines]
        return OcrResult(text, lines, result.truncated)

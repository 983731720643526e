"""Dictionary correction of an offline engine's text: the language prior an LLM reader has built in.

Reconstructed strokes at 6-10 px x-height confuse a few glyph pairs (e/o, i/l, a/o, c/e, s/e/o/a); an
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
* in coherent text the trigram model chooses each lower-case word among its lookalikes
  (``language_model``); a non-word of ``min_edit_length`` letters or more may also be a word one
  letter away (a glyph lost, invented or misread beyond the lookalikes: "knowlecge", "acceptnnce"),
  at a cost the model's context must outweigh (``edit_log_prob``); there a non-word of two letters
  is weighed against its lookalikes too ("Truth bo in the" -> "be");
* in coherent text a period followed by a word in lower case is a comma whose tail was lost
  ("opinion of theirs. that none"), unless the word before it is an abbreviation;
* capitalisation (lower, Capitalised, UPPER) and surrounding punctuation are kept.

The word and word-pair lists are SymSpell's English frequency dictionaries (82,765 words, 242,342
pairs; MIT licence), shipped inside the ``symspellpy`` package; no network is needed. On clean
prose from the corpus 1.4 % of 28-character lines gain a change (archaic and rare words: ere ->
are, confuting -> confusing; ``lab/eval/clean_text.py``), while it removes a third to a half of the
errors on reconstructed pages.
"""

from __future__ import annotations

import logging
import math
import re
import string
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from functools import lru_cache
from itertools import combinations, product
from typing import TYPE_CHECKING, Literal

import numpy as np

from ..errors import OcrUnavailableError
from .base import OcrResult
from .language_model import MODELS as LANGUAGE_MODELS
from .language_model import Candidate, TrigramScorer, load_model, viterbi

if TYPE_CHECKING:
    from symspellpy import SymSpell

    from .base import OcrBackend

logger = logging.getLogger(__name__)

# a capital I read as a one or an l (a bare stroke in a sans-serif face: "Not that 1 can think")
_LONE_I = re.compile(r"^(?P<lead>)(?P<word>[1l])(?P<trail>[,;:!?.]?)$")
_TOKEN = re.compile(r"^(?P<lead>[^A-Za-z]*)(?P<word>[A-Za-z]+)(?P<trail>(?:'[A-Za-z]{1,2})?[^A-Za-z]*)$")  # author's
# (s with e, o and a: a small s whose spine the reconstruction fills in reads as a closed glyph,
# "foundere of our true", "eateem he atoneo"; s and c are kept apart: what each gains and costs,
# cloud/README.md, OCR engines)
_CONFUSABLE_GROUPS = ("eoac", "ilt", "nu", "hb", "rt", "vy", "se", "so", "sa")
CONFUSABLE: frozenset[tuple[str, str]] = frozenset(
    (a, b) for group in _CONFUSABLE_GROUPS for a in group for b in group if a != b
)
_ALTERNATIVES: dict[str, str] = {
    ch: "".join(sorted({b for a, b in CONFUSABLE if a == ch})) for ch in {a for a, _ in CONFUSABLE}
}
DROPPED_STEMS = "ilt"  # thin strokes a reconstruction can lose entirely
_SENTENCE_END = (".", "!", "?", ":", ";")
TextKind = Literal["letters", "words", "text"]
RECENT_PAGES = 64  # corrected texts remembered


# words written with a period that a lower-case word may follow ("etc. and", "cf. the")
_ABBREVIATIONS = frozenset(
    "al approx ca cf ch co dr ed eds eg esp etc fig ibid ie inc jr ltd mr mrs ms no op pp resp sr st viz vol vs".split()
)
_PERIOD_WORD = re.compile(r"^[^A-Za-z]*(?P<word>[A-Za-z]{2,})\.$")


def comma_before_lowercase(text: str) -> str:
    """A period read where the print has a comma: in prose a word and a period followed by a word in
    lower case (on the same line or the next) is a comma whose tail the reconstruction lost
    ("opinion of theirs. that none"), unless the word is an abbreviation."""
    lines = [line.split(" ") for line in text.split("\n")]
    flat = [(k, j) for k, tokens in enumerate(lines) for j, token in enumerate(tokens) if token]
    for (k, j), (k2, j2) in zip(flat, flat[1:]):
        match = _PERIOD_WORD.match(lines[k][j])
        if match and lines[k2][j2][0].islower() and match.group("word").lower() not in _ABBREVIATIONS:
            lines[k][j] = lines[k][j][:-1] + ","
    return "\n".join(" ".join(tokens) for tokens in lines)


def one_edit(read: str) -> set[str]:
    """Every string one letter away from ``read`` (a letter deleted, inserted, replaced, or two
    neighbours swapped): a glyph the engine lost, invented or misread beyond the lookalikes."""
    splits = [(read[:k], read[k:]) for k in range(len(read) + 1)]
    edits = {head + tail[1:] for head, tail in splits if tail}
    edits |= {head + tail[1] + tail[0] + tail[2:] for head, tail in splits if len(tail) > 1}
    edits |= {head + letter + tail[1:] for head, tail in splits if tail for letter in string.ascii_lowercase}
    edits |= {head + letter + tail for head, tail in splits for letter in string.ascii_lowercase}
    edits.discard(read)
    return edits


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
        from importlib.resources import files  # lazy: the word list is read when the first correction needs it

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
    min_lm_length: int = 2  # in coherent text the trigram model weighs the lookalikes of shorter non-words too ("bo" -> "be")
    min_known_fraction: float = 0.3
    min_pair_rate: float = 0.1  # share of adjacent words that are known pairs from which a page is coherent text
    swap_log_prob: float = math.log(1e-4)  # channel: one real word read as a lookalike real word
    fix_log_prob: float = math.log(0.1)  # channel: per lookalike glyph of a non-word's fix
    keep_nonword_log_prob: float = math.log(1e-4)  # channel: a word the dictionary does not know was printed so
    edit_log_prob: float = math.log(1e-5)  # channel: a non-word of ``min_edit_length`` letters or more read one edit
    # from a word beyond the lookalikes ("knowlecge", "acceptnnce"); shorter words have too many such neighbours
    min_edit_length: int = 6
    max_candidates: int = 6  # lookalikes per word the language model weighs (the most frequent)
    language: str = "en"  # the language model of coherent text (``language_model.MODELS``); another: non-word fixes only
    _speller: SymSpell | None = field(default=None, init=False, repr=False)
    _trigrams: TrigramScorer | None = field(default=None, init=False, repr=False)
    _longest: int | None = field(default=None, init=False, repr=False)  # letters of the dictionary's longest word
    _recent: dict[str, str] = field(default_factory=dict, init=False, repr=False)
    _recent_lock: threading.Lock = field(default_factory=threading.Lock, init=False, repr=False)

    def _words(self) -> SymSpell:
        if self._speller is None:
            self._speller = _dictionary()
        return self._speller

    def load(self) -> None:
        """The word lists and the language model, now (OcrUnavailableError when missing)."""
        self._words()
        if self.language in LANGUAGE_MODELS:
            self._scorer()

    def known(self, word: str) -> bool:
        return word.lower() in self._words().words

    def _beyond_words(self, read: str) -> bool:
        """Whether ``read`` is too long to be any dictionary word misread (every fix keeps its length
        or changes it by one letter): a band of noise read as one long token gets no search, whose
        cost grows with the cube of its length."""
        if self._longest is None:
            self._longest = max(map(len, self._words().words))
        return len(read) > self._longest + 1

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
        if len(word) < self.min_length or not word.isalpha() or self._beyond_words(word):
            return False
        counts = self._words().words
        return any(w in counts for w in misreadings(word.lower(), 1))

    def _closest(self, word: str) -> str:
        """The most frequent dictionary word the unknown ``word`` may be a misreading of, or ``word``."""
        read = word.lower()
        if self._beyond_words(read):
            return word
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

    def _correct_line(self, line: str, after_sentence_end: bool, *, sentences: bool = True) -> tuple[str, bool]:
        """The line with its unknown words corrected, and whether it reads as prose (``sentences``:
        a capital I inside a sentence may be a misread i; not in a list of words)."""
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
                in_sentence = sentences and not sentence_start and not match.group("lead")
                out.append(match.group("lead") + self.correct_word(match.group("word"), in_sentence=in_sentence)
                           + match.group("trail"))
            sentence_start = token.endswith(_SENTENCE_END) if token else sentence_start
        return " ".join(out), True

    def text_kind(self, text: str) -> TextKind:
        """What the page is, from its words: ``letters`` (most tokens unknown, no adjacent pair a
        known word pair: random letters, codes), ``words`` (known words that rarely make known
        pairs: a list), or ``text`` (at least ``min_pair_rate`` of adjacent words are known pairs)."""
        words = [m.group("word").lower() for m in (_TOKEN.match(t) for t in text.split()) if m is not None]
        long_words = [w for w in words if len(w) > 1]
        if not long_words:
            return "letters"
        strict = sum(self.known(w) for w in long_words) / len(long_words)
        near = sum(self.known(w) or self._one_glyph_from_known(w) for w in long_words) / len(long_words)
        pairs = self._words().bigrams
        adjacent = list(zip(words, words[1:]))
        pair_rate = sum(f"{a} {b}" in pairs for a, b in adjacent) / len(adjacent) if adjacent else 0.0
        if pair_rate >= self.min_pair_rate:
            return "text"
        # (short random letter groups are often one glyph from some word: "sona", "dop")
        if near < self.min_known_fraction or (pair_rate == 0.0 and strict < 0.5 and near < 0.75):
            return "letters"
        return "words"

    def correct(self, text: str) -> str:
        """Random letters stay as read; a word list gets its non-words fixed, one at a time;
        coherent text gets the language model's pass over the whole page. (A page asked about
        again while it grows reads the same until a line changes: the last few are remembered.)"""
        with self._recent_lock:  # one corrector serves every OCR thread
            if text in self._recent:
                return self._recent[text]
        corrected = self._correct(text)
        with self._recent_lock:
            self._recent[text] = corrected
            while len(self._recent) > RECENT_PAGES:
                del self._recent[next(iter(self._recent))]
        return corrected

    def _correct(self, text: str) -> str:
        kind = self.text_kind(text)
        if kind == "letters":
            return text
        if kind == "words" or self.language not in LANGUAGE_MODELS:  # no language model: non-word fixes only
            return "\n".join(self._correct_line(line, True, sentences=False)[0] for line in text.split("\n"))
        return comma_before_lowercase(self._by_language_model(text))

    # -- coherent text: the noisy channel, scored by the trigram model --

    def _candidates(self, word: str) -> list[Candidate]:
        """What a lower-case ``word`` may have been printed as, with the channel's cost."""
        counts = self._words().words
        read = word.lower()
        if read in counts:
            others = sorted((w for w in set(misreadings(read, 1)) if w in counts), key=counts.__getitem__, reverse=True)
            return [Candidate(read, 0.0), *(Candidate(w, self.swap_log_prob) for w in others[: self.max_candidates - 1])]
        if len(read) < self.min_lm_length:
            return [Candidate(read, 0.0)]
        if self._beyond_words(read):
            return [Candidate(read, self.keep_nonword_log_prob)]
        most = 1 if len(read) <= 4 else (2 if len(read) <= 7 else self.max_substitutions)
        found: dict[str, float] = {}
        # (a lost stem is not looked for in a word of two letters: "ye" is not a misread "yet")
        for level in [1, *([0] if len(read) >= self.min_length else []), *range(2, most + 1)]:
            cost = self.fix_log_prob * max(level, 1)
            for w in misreadings(read, level):
                if w in counts and w not in found:
                    found[w] = cost
            if len(found) >= self.max_candidates:
                break
        if len(read) >= self.min_edit_length:
            for w in one_edit(read):
                if w in counts and w not in found:
                    found[w] = self.edit_log_prob
        ranked = sorted(found, key=lambda w: (-found[w], -counts[w]))[: self.max_candidates]
        # a word the dictionary does not know is itself a sign of a misreading: kept, it costs a glyph's fix
        return [Candidate(read, self.keep_nonword_log_prob), *(Candidate(w, found[w]) for w in ranked)]

    def _by_language_model(self, text: str) -> str:
        """Non-words with a capital (names, sentence starts, a misread I) as in ``_correct_line``;
        every lower-case word chosen among its lookalikes by Viterbi under the trigram model."""
        scorer = self._scorer()
        out_lines: list[list[str]] = []
        slots: list[list[Candidate]] = []
        places: list[tuple[int, int, re.Match[str]]] = []  # (line, token, match) of each slot
        ended = True
        for k, line in enumerate(text.split("\n")):
            tokens = line.split(" ")
            out_lines.append(tokens)
            for j, token in enumerate(tokens):
                lone = _LONE_I.match(token)
                if lone is not None:  # the digit weighed as the number it names
                    slots.append([Candidate("one" if lone.group("word") == "1" else "l", 0.0), Candidate("i", self.fix_log_prob)])
                    places.append((k, j, lone))
                    ended = token.endswith(_SENTENCE_END)
                    continue
                match = _TOKEN.match(token)
                if match is None:
                    if token:
                        ended = token.endswith(_SENTENCE_END)
                    continue
                word = match.group("word")
                if word.islower():
                    slot = self._candidates(word)
                else:
                    in_sentence = not ended and not match.group("lead")
                    fixed = self.correct_word(word, in_sentence=in_sentence)
                    tokens[j] = match.group("lead") + fixed + match.group("trail")
                    slot = [Candidate(fixed.lower(), 0.0)]
                slots.append(slot)
                places.append((k, j, match))
                ended = token.endswith(_SENTENCE_END)
        chosen = viterbi(slots, scorer.log_prob)
        for (k, j, match), slot, word in zip(places, slots, chosen):
            if len(slot) > 1 and word != slot[0].word:
                fixed = "I" if word == "i" else _with_case_of(match.group("word"), word)
                out_lines[k][j] = match.group("lead") + fixed + match.group("trail")
        return "\n".join(" ".join(tokens) for tokens in out_lines)

    def _scorer(self) -> TrigramScorer:
        if self._trigrams is None:
            self._trigrams = TrigramScorer(load_model(self.language))
        return self._trigrams


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
            self.corrector.load()
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

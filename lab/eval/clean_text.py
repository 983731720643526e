"""The correction on text that was read right: what it changes on clean prose.

Every held-out corpus paragraph (the part never used for training, which the suite's texts come
from) is wrapped as the suite prints it (28-character lines, pages of four) and handed to the
cloud's correction as if an engine had read it perfectly. Any line it changes is a correct line
made wrong; the check states the share of lines changed and the CER that adds.
"""

from __future__ import annotations

import textwrap
import time
from dataclasses import dataclass

from darkread.cloud.ocr.lexicon import LexiconCorrector
from darkread.core.text_metrics import error_rates
from darkread.models.synth.text import paragraphs_for

LINE_CHARS = 28
PAGE_LINES = 4


@dataclass(frozen=True)
class CleanTextCheck:
    pages: int
    lines: int
    lines_changed: int
    cer_added: float  # mean over pages
    ms_per_page: float
    examples: tuple[tuple[str, str], ...]  # (printed, after the correction), the first few

    @property
    def changed_share(self) -> float:
        return self.lines_changed / self.lines if self.lines else 0.0


def clean_text_check(corrector: LexiconCorrector | None = None, max_examples: int = 5) -> CleanTextCheck:
    corrector = corrector or LexiconCorrector()
    corrector.load()
    pages = []
    for paragraph in paragraphs_for("held_out"):
        lines = textwrap.wrap(paragraph, width=LINE_CHARS, break_long_words=True, break_on_hyphens=False)
        pages += ["\n".join(lines[k : k + PAGE_LINES]) for k in range(0, len(lines) - PAGE_LINES + 1, PAGE_LINES)]
    changed, total, cer = 0, 0, 0.0
    examples: list[tuple[str, str]] = []
    started = time.perf_counter()
    for page in pages:
        out = corrector.correct(page)
        for printed, corrected in zip(page.split("\n"), out.split("\n")):
            total += 1
            if printed != corrected:
                changed += 1
                if len(examples) < max_examples:
                    examples.append((printed, corrected))
        cer += error_rates(page, out).cer
    seconds = time.perf_counter() - started
    return CleanTextCheck(len(pages), total, changed, cer / max(1, len(pages)), 1000 * seconds / max(1, len(pages)), tuple(examples))


def clean_text_section(check: CleanTextCheck) -> list[str]:
    return [
        "## The correction on clean prose",
        "",
        (f"The cloud's correction (`cloud/ocr/lexicon.py`: letters untouched, word lists non-word fixes only, coherent "
         f"text the trigram model's pass) given {check.pages} pages ({check.lines} lines) of held-out corpus prose as if "
         f"read perfectly (`lab/eval/clean_text.py`): **{100 * check.changed_share:.2f} % of lines changed** "
         f"(goal under 2 %), **{100 * check.cer_added:.3f} % CER added** (goal under 0.1 %), {check.ms_per_page:.1f} ms a page "
         "(includes the error-rate measurement)."),
        "",
        *[f"- `{a}` -> `{b}`" for a, b in check.examples],
        "",
    ]

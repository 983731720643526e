"""The report's "Before and after" section: this evaluation beside an earlier one of the same suite.

``--before FILE`` names a stored ``results.json`` of an earlier report (e.g.
``docs/eval/before/results.json``, kept from the evaluation before the reading became honest:
language mask, correction by kind of text, line judgements). Only recordings both hold are
compared, so a partly evaluated suite still compares like with like.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from pathlib import Path

from darkread.lab.eval.aggregate import group_by, mean, sort_key
from darkread.lab.eval.results import RecordingResult, typed
from darkread.lab.eval.tables import pct


def load_before(path: str | Path) -> list[RecordingResult]:
    doc = json.loads(Path(path).read_text(encoding="utf-8"))
    if not isinstance(doc, list):
        raise ValueError(f"{path}: expected a results.json of an earlier report (a list of recordings)")
    return typed(doc)


def _commits(results: Iterable[RecordingResult]) -> str:
    """The commits the results were evaluated at, as the report names them."""
    found = sorted({r.commit for r in results if r.commit})
    return ", ".join(f"`{c}`" for c in found) if found else "not recorded"


def before_after_section(results: Sequence[RecordingResult], before: Sequence[RecordingResult], source: str) -> list[str]:
    earlier = {r.name: r for r in before}
    pairs = [(r, earlier[r.name]) for r in results if r.name in earlier and r.scanpath == "model"]
    if not pairs:
        return []
    now = [r for r, _ in pairs]
    then = {r.name: b for r, b in pairs}

    def rows(key: str | tuple[str, ...], fmt: object) -> list[str]:
        out = []
        for value, members in sorted(group_by(now, key).items(), key=lambda kv: sort_key(kv[0])):
            a = mean(then[m.name].rate("darkread") for m in members)
            b = mean(m.rate("darkread") for m in members)
            out.append(f"| {fmt(value)} | {len(members)} | {pct(a)} | {pct(b)} |")  # type: ignore[operator]
        return out

    head = "| {} | n | before CER | after CER |\n|---|---:|---:|---:|"
    return [
        "## Before and after",
        "",
        (f"darkread's page CER (mean per recording, clipped at 100 %) on the {len(pairs)} recordings this evaluation and "
         f"the earlier one (`{source}`) both hold: the same recordings, read by the code of the commits named "
         f"(before {_commits(b for _, b in pairs)}, after {_commits(r for r, _ in pairs)})."),
        "",
        head.format("lux"),
        *rows("lux", lambda v: f"{v:g}"),
        f"| **all** | {len(pairs)} | {pct(mean(b.rate('darkread') for _, b in pairs))} | {pct(mean(r.rate('darkread') for r in now))} |",
        "",
        head.format("lux, kind"),
        *rows(("lux", "kind"), lambda v: f"{v[0]:g}, {v[1]}"),
        "",
    ]

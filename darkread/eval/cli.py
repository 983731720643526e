"""``darkread eval SUITE_DIR`` and ``darkread eval make-suite OUT``: evaluation suites and the report."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from darkread.eval.results import RecordingResult

logger = logging.getLogger(__name__)

EVAL_HELP = """\
Two forms:

  darkread eval make-suite OUT [--small] [--jobs N]
      write the evaluation suite (synthetic recordings with fixed seeds over lux 1000/100/30/10/5,
      text kinds, three font families incl. one held out of training, x-heights 7-12, motion
      still/normal/walking, and nine 30-lux paragraphs). Each recording ends when the page has been
      read once; texts come from the corpus part never used for training; six more replay a real
      reader's fixations (30 and 10 lux paragraphs, three motions; names end in _human). --small:
      17 short recordings, one axis varied at a time (CI-sized). --match PATTERN: only those
      recordings (e.g. --match '*lux30_*_human').

  darkread eval SUITE_DIR [--out docs/eval] [--backend local] [--jobs N]
      read every recording of SUITE_DIR (folders with text.txt) end to end, take the RGB baseline
      snapshot of the same scene, compare OCR engines on the stitched pages, measure bandwidth, and
      write the Markdown report with PNG plots to --out. Results are kept per recording under
      SUITE_DIR/eval_runs, so an interrupted evaluation resumes (--force redoes them).
      --report-only rebuilds the report from the stored results.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "eval",
        help="evaluate darkread on a suite of recordings against an RGB snapshot baseline; make suites",
        description=EVAL_HELP,
        usage="darkread eval SUITE_DIR [options]\n       darkread eval make-suite OUT [--small] [--match PATTERN] [--jobs N]",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("target", metavar="SUITE_DIR", help="suite directory, or the word make-suite")
    parser.add_argument("make_suite_out", nargs="?", metavar="OUT", help=argparse.SUPPRESS)
    parser.add_argument("--out", default="docs/eval", metavar="DIR", help="report folder (default docs/eval)")
    parser.add_argument("--backend", default="local", choices=["local", "rapidocr", "tesseract", "google", "openai"],
                        help="OCR engine for darkread and the RGB baseline (default: local)")
    parser.add_argument("--compare", nargs="*", metavar="ENGINE", default=None,
                        help="OCR engines to compare on the stitched pages (default: every installed offline "
                             "engine with and without the word-list correction, e.g. rapidocr and rapidocr-raw, plus "
                             "remote ones when configured; --compare alone: no comparison)")
    parser.add_argument("--model", metavar="ONNX", help="reconstruction model (default: the shipped one)")
    parser.add_argument("--work", metavar="DIR", help="per-recording outputs (default SUITE_DIR/eval_runs)")
    parser.add_argument("--force", action="store_true", help="re-evaluate recordings that already have results")
    parser.add_argument("--report-only", action="store_true", help="rebuild the report from stored results")
    parser.add_argument("--note", action="append", default=[], metavar="TEXT", help="a line for the report's header (repeatable)")
    parser.add_argument("--small", action="store_true", help="make-suite: the small (CI) suite")
    parser.add_argument("--limit", type=int, metavar="N", help="make-suite: only the first N recordings")
    parser.add_argument("--match", metavar="PATTERN",
                        help="make-suite: only recordings whose name matches (shell pattern or substring), e.g. "
                             "'*lux30_*_human' for the real-scanpath recordings at 30 lux")
    parser.add_argument("--infer", default="every-window", choices=["on-change", "every-window"],
                        help="the edge's mode (default every-window: every frame; on-change: one fused view per fixation); "
                             "evaluate both into two --work folders to compare them")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="worker processes (make-suite and evaluation; default 1)")
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    if args.target == "make-suite":
        return _make_suite(args)
    if args.make_suite_out is not None:
        raise ValueError(f"unexpected argument {args.make_suite_out!r}; `darkread eval SUITE_DIR` takes one folder")
    return _evaluate(args)


def _make_suite(args: argparse.Namespace) -> int:
    from darkread.eval.suite import make_suite

    if not args.make_suite_out:
        raise ValueError("give the output folder: darkread eval make-suite OUT [--small]")
    entries = make_suite(args.make_suite_out, small=args.small, only=args.limit, jobs=args.jobs, match=args.match)
    print(f"{len(entries)} recordings in {args.make_suite_out}")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from darkread.edge.reconstruct import default_model_path
    from darkread.eval.provenance import ReportInfo, describe_model, git_commit
    from darkread.eval.report import write_report
    from darkread.eval.runner import evaluate_suite, load_results

    suite = Path(args.target)
    work = Path(args.work) if args.work else suite / "eval_runs"
    if args.report_only:
        results = load_results(work)
        if not results:
            raise FileNotFoundError(f"{work}: no stored results; run `darkread eval {suite}` first")
    else:
        results = evaluate_suite(suite, work, backend=args.backend, compare=args.compare, model=args.model,
                                 force=args.force, jobs=args.jobs, infer=args.infer)
    info = ReportInfo(
        commit=git_commit(),
        backend=args.backend,
        model=describe_model(args.model or default_model_path()),
        suite=_describe_suite(suite, results),
        notes=list(args.note),
    )
    path = write_report(results, args.out, info)
    print(f"report: {path}")
    return 0


def _describe_suite(suite: Path, results: list[RecordingResult]) -> str:
    import json

    seconds = sorted(r.duration_s for r in results if r.duration_s)
    kind = ""
    doc = suite / "suite.json"
    if doc.is_file():
        kind = "small suite, " if json.loads(doc.read_text()).get("small") else "full suite, "
    if not seconds:
        span = "durations unknown"
    elif seconds[0] == seconds[-1]:
        span = f"{seconds[0]:g} s each"
    else:
        span = f"{seconds[0]:.1f}-{seconds[-1]:.1f} s each, {sum(seconds) / 60:.1f} min in all"
    return f"{len(results)} synthetic recordings ({kind}{span}; `darkread eval make-suite`, fixed seeds)"

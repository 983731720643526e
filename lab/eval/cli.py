"""``darkread eval FORM ...``: evaluation suites, the report, and the lab's questions about them."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from darkread.lab.eval.calibrate import CalibrationCheck
    from darkread.lab.eval.results import RecordingResult

from darkread.edge.config import INFER_MODES, default_infer_mode, other_infer_mode
from darkread.edge.sources.evk4.bias_profiles import BIAS_PROFILES
from darkread.lab.synth.simulators import SIMULATORS
from darkread.models.synth.motion import MOTION_REGIMES
from darkread.models.synth.sensor import K_NAMED, REGIMES, STANDARD_LAWS

DEFAULT_CONFIDENCE_MODEL = Path(__file__).resolve().parents[2] / "cloud" / "data" / "line_confidence.json"

logger = logging.getLogger(__name__)
BOTH = "both"

EVAL_HELP = """\
Seven forms:

  darkread eval make-suite OUT [--small | --subset simulator-check] [--simulator darkread|hesim] [--font FAMILY] [--jobs N]
      write the evaluation suite (synthetic recordings with fixed seeds over lux 1000/100/30/10/5,
      text kinds, three font families incl. one held out of training, x-heights 7-12, motion
      still/normal/walking, and nine 30-lux paragraphs). Each recording ends when the page has been
      read once; texts come from the corpus part never used for training; six more replay a real
      reader's fixations (30 and 10 lux paragraphs, three motions; names end in _human). --small:
      17 short recordings, one axis varied at a time (CI-sized). --match PATTERN: only those
      recordings (e.g. --match '*lux30_*_human'). --simulator hesim: the same scenes, gaze and
      texts turned into events by a second, independent simulator (hesim-3d); --subset
      simulator-check: the 18 recordings `make eval-hesim` compares on both simulators. --font
      FAMILY: the selected recordings made again in another font family, all else alike (names end
      in _as_<their own family>), to tell what a font costs from what a scene does.

  darkread eval run SUITE_DIR [--out docs/eval] [--backend local] [--infer MODE|both] [--beside DIR] [--jobs N]
      read every recording of SUITE_DIR (folders with text.txt) end to end, take the RGB baseline
      snapshot of the same scene, compare OCR engines on the stitched pages, measure bandwidth, and
      write the Markdown report with PNG plots to --out. Results are kept per recording under
      SUITE_DIR/eval_runs/<mode> (or --work), so an interrupted evaluation resumes (--force redoes
      them). --report-only rebuilds the report from the stored results. --match PATTERN: only those
      recordings (e.g. --match '*_lux10_*', with a --work folder of their own).

  darkread eval compare-simulators OURS_SUITE OTHER_SUITE [--out FILE.md] [--infer MODE]
      the same recordings made by two event simulators (make-suite --simulator), both evaluated:
      mean CER per lux and per lux x motion side by side, with each suite's event rates; printed and
      written to --out (a .md file, or a folder: FOLDER/simulators.md; default docs/eval/simulators.md,
      which the report of docs/eval then shows as its "Second simulator" section). `make eval-hesim`
      runs it all.

  darkread eval head-motion RECORDING... [--out FILE.md]
      the head's motion from the gyroscope (closed_loop_trajectory.csv) and from the events' tracker,
      each against the simulator's true pose: median error per 20-ms slice (docs/head_motion.md).

  darkread eval attribute SUITE_DIR [--work DIR] [--out FILE.md] [--infer MODE] [--model ONNX]
      where an evaluated suite's errors come from: each recording read again end to end with the
      head's motion known exactly (the edge given the simulator's pose: what an exact inertial sensor would
      give), each page read again with its frames placed by the simulator's true pose (perfect
      stitching) and with every frame replaced by its window's true ink (perfect frames), and each
      frame's ink recall and precision against that truth; mean CER of the four by lux and motion,
      printed and written to --out (a .md file, or a folder: FOLDER/attribution.md) with the
      per-recording figures beside it (.json). --model: the network the suite was evaluated with.

  darkread eval restitch SUITE_DIR [--work DIR] [--out FILE.md] [--before FILE.json] [--infer MODE]
      an evaluated suite's stored frames stitched and read again by the cloud code of now, so a change
      to the stitcher or the reading is measured on the very same frames, in a minute instead of an
      end-to-end run's quarter hour: CER as evaluated and re-read, and each frame's place against the
      simulator's truth (registration error, frames misplaced), by lux and motion; --before: the
      .json an earlier run wrote beside its report, shown beside. Written to --out (a .md file, or
      a folder: FOLDER/restitch.md) with the per-recording figures beside it (.json).

  darkread eval evidence SUITE_DIR [--out FILE.md] [--jobs N]
      how much of the ink the events themselves show, the bound on what any network can draw: for
      windows of each synthetic recording cut as the edge cuts them (1600 events, and 3200 and 6400:
      what temporal context could gather), with the head's motion as the edge measures it and known
      exactly, the chance that an ink pixel has more events than a paper pixel, and the share of
      ink with an event within 1 px; by lux and motion, written to --out (a .md file, or a folder:
      FOLDER/evidence.md) with the per-recording figures beside it (.json). Needs no evaluation.

  darkread eval calibrate SUITE_DIR [--work DIR] [--model-out FILE.json] [--out DIR] [--target-risk R]
      fit the cloud's line-confidence model on an evaluated suite's lines (each right or wrong by its
      CER; recordings 0-3, 8-11, ... fit it, 4-7, 12-15, ... are held out), write it (default
      cloud/data/line_confidence.json, what the cloud ships) and its calibration on the held-out
      lines (calibration.md, reliability.png with the ECE) to --out; then rebuild the report
      (--report-only) to see coverage and risk under it.

  darkread eval check-confidence SUITE_DIR [SUITE_DIR ...] [--model FILE.json]
      the line-confidence model's calibration (ECE) on evaluated suites, e.g. ones it was not fitted
      on: each suite's read lines and their held-out half, then all of them pooled.

  darkread eval side-by-side LABEL=SUITE_DIR [LABEL=SUITE_DIR ...] --out FILE.md [--reference LABEL]
      several evaluated suites of the same scenes (made with the same selection, e.g. by another
      sensor regime, bias profile, K or head motion) side by side: mean CER per light level and per
      light and motion, each row on the recordings all suites hold, the difference to --reference
      in points, the RGB snapshot beside, and a CER-vs-lux plot (FILE.png).

  Two edge modes side by side: --infer both evaluates the default mode (the edge's own default,
  PipelineConfig().infer) and the other one, each into its own folder (--work and --beside,
  default SUITE_DIR/eval_runs/<mode>), and the report puts the other mode beside the default:
  CER by lux and motion with the difference, the 30-lux headline, a CER-vs-lux plot of both, and
  each mode's stream in the bandwidth table. --beside DIR alone puts the stored results of another
  run (the other mode, same suite) beside this one without evaluating them, e.g.
      darkread eval run SUITE --infer on-change --work W1 --beside SUITE/eval_runs/every-window
"""


def _common_options() -> argparse.ArgumentParser:
    """Options every form that reads a suite shares."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--out", default="docs/eval", metavar="DIR", help="where the report goes (default docs/eval)")
    common.add_argument("--backend", default="local", choices=["local", "rapidocr", "tesseract", "google", "openai"],
                        help="OCR engine for darkread and the RGB baseline (default: local)")
    common.add_argument("--model", metavar="ONNX", help="reconstruction model (default: the shipped one)")
    common.add_argument("--work", metavar="DIR",
                        help="per-recording outputs of the (default) mode (default SUITE_DIR/eval_runs/<mode>)")
    common.add_argument("--note", action="append", default=[], metavar="TEXT", help="a line for the report's header (repeatable)")
    common.add_argument("--infer", default=None, choices=[*INFER_MODES, BOTH],
                        help="the edge's mode (default: the edge's default, PipelineConfig().infer; every-window: every frame; "
                             "on-change: one fused view per fixation; both: the default and the other beside it)")
    common.add_argument("--jobs", type=int, default=1, metavar="N", help="worker processes (default 1)")
    return common


def _add_run(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = sub.add_parser("run", parents=[common], help="read every recording of a suite end to end and write the report",
                       description="Read every recording of SUITE_DIR end to end, take the RGB baseline snapshot of the same "
                                   "scene, compare OCR engines on the stitched pages, measure bandwidth, and write the report.")
    p.add_argument("target", metavar="SUITE_DIR", help="a suite made by `darkread eval make-suite`")
    p.add_argument("--compare", nargs="*", metavar="ENGINE", default=None,
                   help="OCR engines to compare on the stitched pages (default: every installed offline engine with and "
                        "without the word-list correction, plus remote ones when configured; --compare alone: no comparison)")
    p.add_argument("--force", action="store_true", help="re-evaluate recordings that already have results")
    p.add_argument("--report-only", action="store_true", help="rebuild the report from stored results")
    p.add_argument("--beside", metavar="DIR",
                   help="results of the other mode to put beside this run in the report (a --work folder of the same "
                        "suite); with --infer both, where the other mode is evaluated (default SUITE_DIR/eval_runs/<mode>)")
    p.add_argument("--no-rgb", action="store_true",
                   help="leave out the RGB baseline and the bandwidth figures (they need its snapshot): darkread's "
                        "reading only, e.g. for a second simulator's suite whose scenes another suite already has")
    p.add_argument("--edge-shed-level", type=int, choices=range(4), default=0, metavar="{0,1,2,3}",
                   help="hold the edge at this shedding level for every read (edge.load: 1 a view's frames capped at "
                        "two, 2 at one, 3 also no view where the last one covers the window), as a live edge starved of "
                        "CPU sheds; the views say so and the cloud's line confidence takes it in (default 0: none); give "
                        "it its own --work folder")
    p.add_argument("--before", metavar="RESULTS.json",
                   help="an earlier report's results.json of the same suite: the report compares darkread's CER by lux "
                        "and kind on the recordings both hold (e.g. docs/eval/before/results.json)")
    p.add_argument("--match", metavar="PATTERN", action="append", default=[],
                   help="only the recordings whose name matches (shell pattern or substring; repeatable), e.g. "
                        "'*_lux10_*': read and reported (give them a --work folder of their own)")
    p.set_defaults(func=_evaluate)


def k_of(text: str) -> float:
    """``--k``: a photoreceptor K in Hz per chip-lux, or one of the band's named points."""
    if text in K_NAMED:
        return K_NAMED[text]
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of Hz per chip-lux nor one of "
                                         f"{', '.join(K_NAMED)}") from None


def _add_make_suite(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("make-suite", help="write the evaluation suite (synthetic recordings with fixed seeds)",
                       description="Write the evaluation suite: synthetic recordings with fixed seeds over lux, text kinds, "
                                   "fonts, x-heights and motion (see `darkread eval --help`).")
    p.add_argument("make_suite_out", metavar="OUT", help="the suite's folder")
    p.add_argument("--small", action="store_true", help="the small (CI) suite")
    p.add_argument("--limit", type=int, metavar="N", help="only the first N recordings")
    p.add_argument("--match", metavar="PATTERN", action="append",
                   help="only recordings whose name matches (shell pattern or substring), e.g. '*lux30_*_human' for the "
                        "real-scanpath recordings at 30 lux (repeatable: any of them)")
    p.add_argument("--subset", choices=["simulator-check"],
                   help="a named part of the full suite; simulator-check: its words and paragraph recordings at 30, 10 "
                        "and 5 lux, every motion (18, same names, seeds and texts)")
    p.add_argument("--simulator", choices=SIMULATORS, default="darkread",
                   help="what turns the rendered scenes into events: darkread (our sensor model, default) or hesim "
                        "(hesim-3d's H-ESIM, IMX636 preset; `make hesim` installs it)")
    p.add_argument("--regime", default="standard", choices=REGIMES,
                   help="our simulator's sensor regime (default standard); fast-photoreceptor: a photoreceptor that keeps "
                        "up in the dark (an optimistic ablation); grounded: the laws fitted to published IMX636 measurements")
    p.add_argument("--sensor-profile", metavar="PROFILE",
                   help="with --regime grounded: draw the sensor around this measured profile (`darkread calibrate sensor`): "
                        "K within +-10 %% (or its stated uncertainty), the noise process fitted to its curve")
    p.add_argument("--motion-regime", default="standard", choices=MOTION_REGIMES,
                   help="the head motion's draws (default standard); grounded: tremor and reading motion from measurements "
                        "drawn across their bands; quiet, central, strong: every band at its low end, centre or high end "
                        "(the same scenes; docs/head_motion_model.md)")
    p.add_argument("--biases", default="factory", choices=sorted(BIAS_PROFILES), metavar="PROFILE",
                   help="with --regime grounded: the IMX636 bias profile the sensor runs (factory, default, or dark: "
                        "the profile the glasses switch to below 15 lux; docs/sensor_model.md)")
    p.add_argument("--k", type=k_of, metavar="K",
                   help="with --regime grounded: the photoreceptor's K fixed instead of drawn over its band, in Hz per "
                        "chip-lux or by name: slow (40), central (130), fast (400); every other draw stays the same")
    p.add_argument("--standard-law", action="append", default=[], choices=STANDARD_LAWS, metavar="LAW",
                   help="with --regime grounded: put this law back to the standard model's, at its draws' centre "
                        f"({', '.join(STANDARD_LAWS)}; repeatable): one at a time, the suites tell what each law decides")
    p.add_argument("--font", metavar="FAMILY",
                   help="every selected recording not already in this font family made again in it (same seed, light, "
                        "motion, text kind and x-height; named <name-in-FAMILY>_as_<old family>)")
    p.add_argument("--jobs", type=int, default=1, metavar="N", help="worker processes (default 1)")
    p.set_defaults(func=_make_suite)


def _add_side_by_side(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("side-by-side", help="several evaluated suites of the same scenes side by side (CER by light and motion)",
                       description="Several evaluated suites of the same scenes side by side: mean CER per light level and "
                                   "per light and motion, each row on the recordings all suites hold.")
    p.add_argument("suites", nargs="+", metavar="LABEL=SUITE_DIR",
                   help="an evaluated suite and its column label (results in SUITE_DIR/eval_runs/<mode>, or "
                        "LABEL=SUITE_DIR:WORK_DIR)")
    p.add_argument("--out", required=True, metavar="FILE.md", help="the Markdown page (the plot goes beside it as FILE.png)")
    p.add_argument("--title", default="Suites side by side", help="the page's title")
    p.add_argument("--reference", metavar="LABEL", help="a column the others are compared with (difference in points)")
    p.add_argument("--note", action="append", default=[], metavar="TEXT", help="a paragraph under the title (repeatable)")
    p.add_argument("--infer", choices=list(INFER_MODES), help="the edge mode whose results are read (default: the edge's)")
    p.set_defaults(func=_side_by_side)


def _side_by_side(args: argparse.Namespace) -> int:
    import shlex
    import sys

    from darkread.lab.eval.side_by_side import LabelledSuite, write_side_by_side

    mode = args.infer or default_infer_mode()
    suites = [LabelledSuite.load(spec, mode) for spec in args.suites]
    command = "darkread " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:2] == ["eval"] else ""
    path = write_side_by_side(suites, Path(args.out), title=args.title, reference=args.reference, notes=args.note,
                              command=command)
    print(f"{len(suites)} suites side by side: {path}")
    return 0


def _add_compare_simulators(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare-simulators", help="the same recordings made by two event simulators, side by side",
                       description="Mean CER per lux and per lux x motion of two evaluated suites made by two simulators.")
    p.add_argument("make_suite_out", metavar="OURS_SUITE")
    p.add_argument("second_suite", metavar="OTHER_SUITE")
    p.add_argument("--out", default="docs/eval", metavar="FILE.md", help="a .md file, or a folder: FOLDER/simulators.md")
    p.add_argument("--infer", default=None, choices=INFER_MODES, help="the edge mode both suites were evaluated in")
    p.set_defaults(func=_compare_simulators)


def _add_one_suite_form(sub: argparse._SubParsersAction, common: argparse.ArgumentParser, name: str, help_text: str,
                        handler: Callable[[argparse.Namespace], int]) -> argparse.ArgumentParser:
    p = sub.add_parser(name, parents=[common], help=help_text, description=help_text)
    p.add_argument("make_suite_out", metavar="SUITE_DIR")
    p.set_defaults(func=handler)
    return p


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "eval", help="evaluate darkread on a suite of recordings against an RGB snapshot baseline; make suites",
        description=EVAL_HELP, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.set_defaults(func=lambda _args: (parser.print_help(), 2)[1], second_suite=None)
    sub = parser.add_subparsers(dest="eval_command", metavar="FORM")
    common = _common_options()
    _add_make_suite(sub)
    _add_run(sub, common)
    _add_compare_simulators(sub)
    _add_side_by_side(sub)
    _add_one_suite_form(sub, common, "attribute", "where an evaluated suite's errors come from (head motion, stitching, frames)",
                        _attribute)
    restitch = _add_one_suite_form(sub, common, "restitch", "an evaluated suite's stored frames stitched and read again by "
                                   "the cloud code of now (a stitcher change measured on the same frames)", _restitch)
    restitch.add_argument("--before", metavar="FILE.json", help="an earlier run's figures (the .json beside its report), "
                          "shown beside these")
    _add_one_suite_form(sub, common, "evidence", "how much of the ink the events themselves show", _evidence)
    calibrate = _add_one_suite_form(sub, common, "calibrate", "fit the cloud's line-confidence model on an evaluated suite",
                                    _calibrate)
    calibrate.add_argument("--model-out", metavar="FILE.json", default=str(DEFAULT_CONFIDENCE_MODEL),
                           help="where the fitted line-confidence model goes (default: the one the cloud ships)")
    _add_head_motion(sub)
    _add_add_imu(sub)
    _add_check_confidence(sub)
    calibrate.add_argument("--target-risk", type=float, default=0.05, metavar="R",
                           help="the CER the answered lines of the fitting half may have (sets the answer threshold)")
    calibrate.add_argument("--also", action="append", default=[], metavar="SUITE_DIR",
                           help="another evaluated suite (or a --work folder of results) whose lines join the fit and the "
                                "held-out measure, split by the same recording numbers (e.g. the suite re-made on another "
                                "sensor model, or read with --edge-shed-level; repeatable)")


def _add_check_confidence(sub: argparse._SubParsersAction) -> None:
    help_text = "the line-confidence model's calibration (ECE) on evaluated suites, e.g. ones it was not fitted on"
    p = sub.add_parser("check-confidence", help=help_text, description=help_text + ": every suite's read lines, "
                       "and their held-out half (the recording numbers `darkread eval calibrate` holds out).")
    p.add_argument("suites", nargs="+", metavar="SUITE_DIR", help="evaluated suites (results in SUITE_DIR/eval_runs/<mode>)")
    p.add_argument("--model", metavar="FILE.json", help="the model to check (default: the one the cloud ships)")
    p.add_argument("--infer", choices=list(INFER_MODES), help="the edge mode whose results are read (default: the edge's)")
    p.set_defaults(func=_check_confidence)


def _check_confidence(args: argparse.Namespace) -> int:
    from darkread.cloud.confidence import load_model
    from darkread.lab.eval.calibrate import check
    from darkread.lab.eval.runner import load_results
    from darkread.lab.eval.selective import outcomes

    model = load_model(args.model)
    mode = args.infer or default_infer_mode()
    pooled = []
    for suite in map(Path, args.suites):
        folder = suite / "eval_runs" / mode
        if not folder.is_dir():
            raise FileNotFoundError(f"{suite}: no results in {folder}; run `darkread eval run {suite}` first")
        lines = outcomes(load_results(folder), suite=str(suite))
        pooled += lines
        if lines and len(args.suites) > 1:
            print(_check_line(str(suite), check(lines, model)))
    print(_check_line("all" if len(args.suites) > 1 else args.suites[0], check(pooled, model)))
    return 0


def _check_line(label: str, result: CalibrationCheck) -> str:
    held = f"{result.held_ece:.3f} on its held-out {result.held_lines}" if result.held_ece is not None else "no held-out lines"
    return (f"{label}: {result.lines} lines of {result.recordings} recordings, {100 * result.right_share:.0f} % right; "
            f"ECE {result.ece:.3f} ({held})")


def _add_head_motion(sub: argparse._SubParsersAction) -> None:
    help_text = "the gyroscope's head motion and the event tracker's against the simulator's true pose, per 20-ms slice"
    p = sub.add_parser("head-motion", help=help_text, description=help_text)
    p.add_argument("recordings", nargs="+", metavar="RECORDING", help="synthetic recordings with closed_loop_trajectory.csv")
    p.add_argument("--out", default=None, metavar="FILE.md", help="also write the table there (and a .json beside it)")
    p.set_defaults(func=_head_motion)


def _add_add_imu(sub: argparse._SubParsersAction) -> None:
    help_text = ("give a suite made before recordings carried a gyroscope the closed_loop_trajectory.csv each would "
                 "carry now (byte for byte, from its spec.json); nothing else changes, so the same scenes read with "
                 "and without it")
    p = sub.add_parser("add-imu", help=help_text, description=help_text)
    p.add_argument("make_suite_out", metavar="SUITE_DIR", help="a suite made by `darkread eval make-suite`")
    p.set_defaults(func=_add_imu)


def _add_imu(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from darkread.lab.synth.rgb_camera import SPEC_NAME, recording_spec
    from darkread.models.synth.recording import add_gyroscope

    folders = sorted(p.parent for p in Path(args.make_suite_out).glob(f"*/{SPEC_NAME}"))
    if not folders:
        raise ValueError(f"{args.make_suite_out}: no recording with a {SPEC_NAME} (make one with `darkread eval make-suite`)")
    for folder in tqdm(folders, unit="rec", desc="gyroscope"):
        add_gyroscope(folder, recording_spec(folder))
    print(f"{len(folders)} recordings in {args.make_suite_out} carry a gyroscope")
    return 0


def _head_motion(args: argparse.Namespace) -> int:
    from darkread.lab.eval.head_motion import write_head_motion

    print(write_head_motion(args.recordings, Path(args.out) if args.out else None), end="")
    return 0


def _make_suite(args: argparse.Namespace) -> int:
    from darkread.lab.eval.suite import make_suite

    entries = make_suite(args.make_suite_out, small=args.small, only=args.limit, jobs=args.jobs, match=args.match,
                         subset=args.subset, simulator=args.simulator, font=args.font, regime=args.regime,
                         sensor_profile=args.sensor_profile, motion_regime=args.motion_regime, biases=args.biases,
                         k=args.k, standard_laws=args.standard_law)
    print(f"{len(entries)} recordings in {args.make_suite_out}")
    return 0


def _compare_simulators(args: argparse.Namespace) -> int:
    from darkread.lab.eval.simulators import SIMULATORS_NAME, write_comparison

    out = Path(args.out)
    out = out / SIMULATORS_NAME if out.suffix != ".md" else out
    path = write_comparison(args.make_suite_out, args.second_suite, out, mode=args.infer or default_infer_mode())
    print(path.read_text())
    return 0


def _first_mode(args: argparse.Namespace) -> str:
    """The edge mode an evaluation reads first: --infer's, or the edge's default (for none or both)."""
    return default_infer_mode() if args.infer in (None, BOTH) else args.infer


def _one_suite(args: argparse.Namespace, usage: str) -> Path:
    """The one suite folder a form that reads a suite (``attribute``, ``evidence``) was given; ``usage``
    is the error when there is not exactly one."""
    if not args.make_suite_out or args.second_suite is not None:
        raise ValueError(usage)
    suite = Path(args.make_suite_out)
    if not suite.is_dir():
        raise FileNotFoundError(f"{suite}: no such suite directory")
    return suite


def _attribute(args: argparse.Namespace) -> int:
    from darkread.lab.eval.attribution import ATTRIBUTION_NAME, write_attribution

    suite = _one_suite(args, "give one evaluated suite: darkread eval attribute SUITE_DIR [--work DIR] [--out FILE.md]")
    work = Path(args.work) if args.work else suite / "eval_runs" / _first_mode(args)
    out = Path(args.out)
    out = out / ATTRIBUTION_NAME if out.suffix != ".md" else out
    path = write_attribution(suite, work, out, backend=args.backend, notes=args.note, model=args.model)
    print(path.read_text())
    return 0


def _restitch(args: argparse.Namespace) -> int:
    from darkread.lab.eval.restitch import RESTITCH_NAME, write_restitch

    suite = _one_suite(args, "give one evaluated suite: darkread eval restitch SUITE_DIR [--work DIR] [--out FILE.md]")
    work = Path(args.work) if args.work else suite / "eval_runs" / _first_mode(args)
    out = Path(args.out)
    out = out / RESTITCH_NAME.replace(".json", ".md") if out.suffix != ".md" else out
    path = write_restitch(suite, work, out, backend=args.backend, before=Path(args.before) if args.before else None,
                          notes=args.note)
    print(path.read_text())
    return 0


def _evidence(args: argparse.Namespace) -> int:
    from darkread.lab.eval.evidence import write_evidence

    suite = _one_suite(args, "give one suite: darkread eval evidence SUITE_DIR [--out FILE.md] [--jobs N]")
    path = write_evidence(suite, args.out, jobs=max(1, args.jobs))
    print(path.read_text())
    return 0


def _calibrate(args: argparse.Namespace) -> int:
    from darkread.lab.eval.calibrate import calibrate
    from darkread.lab.eval.runner import RESULT_NAME, load_results
    from darkread.lab.eval.selective import outcomes

    suite = _one_suite(args, "give one evaluated suite: darkread eval calibrate SUITE_DIR [--work DIR] [--model-out FILE.json]")
    work = Path(args.work) if args.work else suite / "eval_runs" / _first_mode(args)
    if not 0 < args.target_risk < 1:
        raise ValueError(f"--target-risk {args.target_risk:g}: give a CER between 0 and 1")
    lines = outcomes(load_results(work), suite=str(suite))
    sources = [f"{suite} ({len(lines)} lines)"]
    for other in args.also:
        folder = Path(other) / "eval_runs" / _first_mode(args)
        if not folder.is_dir() and any(Path(other).glob(f"*/{RESULT_NAME}")):
            folder = Path(other)  # a --work folder of its own (e.g. the suite read by a shedding edge)
        more = outcomes(load_results(folder), suite=str(other))
        if not more:
            raise FileNotFoundError(f"--also {other}: no judged lines in {folder}; run `darkread eval run {other}` first")
        lines += more
        sources.append(f"{other} ({len(more)} lines)")
    model, ece = calibrate(lines, Path(args.model_out), Path(args.out), args.target_risk, sources=sources)
    print(f"{len(lines)} lines; held-out ECE {ece:.3f}; answer threshold {model.answer_threshold:g}; "
          f"model: {args.model_out}; calibration: {Path(args.out) / 'calibration.md'}")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from darkread.edge.reconstruct import default_model_path
    from darkread.lab.eval.before_after import load_before
    from darkread.lab.eval.provenance import ReportInfo, describe_model, git_commit
    from darkread.lab.eval.report import write_report

    suite = Path(args.target)
    if not suite.is_dir():
        raise FileNotFoundError(f"{suite}: no such suite directory")
    mode = _first_mode(args)
    runs = [(mode, Path(args.work) if args.work else suite / "eval_runs" / mode)]
    if args.infer == BOTH or args.beside:
        other = other_infer_mode(mode)
        runs.append((other, Path(args.beside) if args.beside else suite / "eval_runs" / other))
    evaluate = [] if args.report_only else runs if args.infer == BOTH else runs[:1]
    per_mode = [_results(suite, work, expected, args, evaluate=(expected, work) in evaluate) for expected, work in runs]
    info = ReportInfo(
        commit=git_commit(),
        backend=args.backend,
        model=describe_model(args.model or default_model_path()),
        suite=_describe_suite(suite, per_mode[0]),
        notes=list(args.note),
    )
    before = (args.before, load_before(args.before)) if args.before else None
    path = write_report(per_mode[0], args.out, info, beside=per_mode[1] if len(per_mode) > 1 else None,
                        suite_dir=suite, before=before)
    print(f"report: {path}")
    return 0


def _results(suite: Path, work: Path, mode: str, args: argparse.Namespace, *, evaluate: bool) -> list[RecordingResult]:
    """One mode's results: evaluated (resuming from ``work``) or read from ``work``; all of ``mode`` (those
    ``--match`` names, when given)."""
    from darkread.lab.eval.runner import evaluate_suite, load_results
    from darkread.lab.eval.suite import name_matches

    if evaluate:
        return evaluate_suite(suite, work, backend=args.backend, compare=args.compare, model=args.model, rgb=not args.no_rgb,
                              force=args.force, jobs=args.jobs, infer=mode, shed_level=args.edge_shed_level,
                              match=args.match)
    results = [r for r in load_results(work) if not args.match or name_matches(r.name or "", args.match)]
    if not results:
        raise FileNotFoundError(f"{work}: no stored results; run `darkread eval run {suite} --infer {mode} --work {work}` first")
    others = sorted({r.infer for r in results} - {mode})
    if others:
        raise ValueError(f"{work}: expected {mode} results, found {', '.join(others)} ones; give the folder of a {mode} run")
    return results


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

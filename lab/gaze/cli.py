"""``darkread gaze lines``: the line of every fixation of recorded readings, by darkread's line logic."""

from __future__ import annotations

import argparse
import json
import sys

LINES_HELP = """\
Assign every fixation of FIXATIONS.json (drift format: {"trial_id": {"passage_id": ...,
"fixations": {"__FixationSequence__": [{"x", "y", "start", "end"}, ...]}}}, screen pixels and ms)
to a printed line of its passage in --passages (drift format: {"passage_id": {"__TextBlock__":
{"position", "font_size", "line_height", "text"}}}, a monospaced font). Lines are numbered from 0;
null is a fixation assigned to no line.

Default method: the vote of eyekit's slice, warp and stretch methods (Carr et al. 2022), which
put 99.6 % of the 24 adult drift readers' fixations on their gold line (the stitcher's own
return-sweep logic, --method stitcher: 95.2 %). Under ~1 deg of tracker noise eyekit's warp
holds best (84 %); see docs/gaze.md.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    gaze = subparsers.add_parser("gaze", help="gaze logic on recorded fixations (line assignment)",
                                 description="Gaze logic of darkread applied to recorded eye movements.")
    sub = gaze.add_subparsers(dest="gaze_command", metavar="SUBCOMMAND")
    gaze.set_defaults(func=lambda args: (gaze.print_help(), 2)[1])
    lines = sub.add_parser("lines", help="the printed line of every fixation (JSON per trial)", description=LINES_HELP,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    lines.add_argument("fixations", metavar="FIXATIONS.json", help="fixation file in the drift format")
    lines.add_argument("--passages", required=True, metavar="PASSAGES.json", help="text layout of the passages")
    lines.add_argument("--method", default="vote",
                       help="vote (default: slice+warp+stretch), stitcher, or one eyekit method: chain, cluster, "
                            "merge, regress, segment, slice, split, stretch, warp; or several joined by '+' (a vote)")
    lines.add_argument("--json", action="store_true", help='print {"trial_id": [line or null, ...]} (the only output form)')
    lines.set_defaults(func=_lines)


def _method(name: str):
    from darkread.lab.gaze.lines import DEFAULT_METHOD, EYEKIT_METHODS, STITCHER

    if name == "vote":
        return DEFAULT_METHOD
    if name == STITCHER:
        return STITCHER
    parts = tuple(name.split("+"))
    unknown = [p for p in parts if p not in EYEKIT_METHODS]
    if unknown:
        raise ValueError(f"--method {name!r}: unknown method {unknown[0]!r} (see --help)")
    if len(parts) == 2:
        raise ValueError("--method: a vote needs at least three methods")
    return parts[0] if len(parts) == 1 else parts


def _lines(args: argparse.Namespace) -> int:
    from darkread.lab.gaze import human
    from darkread.lab.gaze.lines import STITCHER, eyekit_available, fixation_lines

    method = _method(args.method)
    if method != STITCHER and (why := eyekit_available()):
        raise ValueError(why)
    try:
        passages = human.load_passages(args.passages)
        trials = human.load_fixation_trials(args.fixations)
    except (KeyError, TypeError, AttributeError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{args.fixations} / {args.passages}: not in the drift format ({type(exc).__name__}: {exc})") from None
    out = {}
    for tid, trial in trials.items():
        if trial.passage_id not in passages:
            raise ValueError(f"trial {tid}: passage {trial.passage_id!r} is not in {args.passages}")
        got = fixation_lines(trial.x, trial.y, trial.start_ms, trial.end_ms, passages[trial.passage_id], method)
        out[tid] = [int(v) if v >= 0 else None for v in got]
    try:
        sys.stdout.write(json.dumps(out) + "\n")
        sys.stdout.flush()
    except BrokenPipeError:  # the reader (e.g. head) stopped early: not an error of ours
        pass
    return 0

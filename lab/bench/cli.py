"""``darkread bench`` (and ``python -m darkread.lab.bench``, ``make bench``): run every benchmark,
print one table, write bench.json."""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

from darkread.lab.bench import BENCH_MODULES, BenchContext, Figure
from darkread.lab.shared_data import find_shared_data

BENCHMARKS = tuple(name.rsplit(".", 1)[-1] for name in BENCH_MODULES)
DESCRIPTION = "Run darkread's benchmarks, each next to a reference measured in the same run; print one table and write bench.json."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--only", nargs="*", choices=BENCHMARKS, metavar="NAME",
                        help=f"run only these benchmarks ({', '.join(BENCHMARKS)})")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    parser.add_argument("--smoke", action="store_true",
                        help="tiny inputs, one repetition: every figure is written, none is meaningful (for tests)")
    parser.add_argument("--out", default="bench.json", help="where to write the figures (default bench.json)")
    parser.add_argument("--cache", default=str(default_cache()), metavar="DIR",
                        help="where inputs that take minutes to simulate are kept between runs (default %(default)s)")


def default_cache() -> Path:
    """``$XDG_CACHE_HOME/darkread/bench`` (``~/.cache/darkread/bench``)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "darkread" / "bench"


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("bench", help="the benchmarks (lab): speed and memory against same-run references",
                                   description=DESCRIPTION)
    add_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    logging.getLogger().setLevel(logging.WARNING)
    figures: list[Figure] = []
    with tempfile.TemporaryDirectory(prefix="darkread-bench-") as scratch:
        ctx = BenchContext(shared_data=find_shared_data(), scratch=Path(scratch), quick=args.quick, smoke=args.smoke,
                           cache=Path(args.cache))
        for name in BENCH_MODULES:
            short = name.rsplit(".", 1)[-1]
            if args.only and short not in args.only:
                continue
            try:
                module = importlib.import_module(name)
            except ModuleNotFoundError as exc:
                if exc.name == name:
                    continue
                raise
            started = time.perf_counter()
            print(f"[bench] {short} ...", file=sys.stderr, flush=True)
            figures.extend(module.run(ctx))
            print(f"[bench] {short} done in {time.perf_counter() - started:.1f} s", file=sys.stderr, flush=True)
        notes = ctx.notes
    width = max((len(f.label) for f in figures), default=10)
    print(f"{'figure':<{width}}  {'value':>12}  {'reference (same run)':<40}  goal")
    for f in figures:
        print(f"{f.label:<{width}}  {f.value:>12.4g}  {f.reference:<40}  {f.goal}")
    for note in notes:
        print(f"note: {note}")
    Path(args.out).write_text(json.dumps({f.key: f.value for f in figures}, indent=1, sort_keys=True) + "\n")
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


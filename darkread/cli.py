"""The single ``darkread`` command.

Each component adds its own sub-commands through a ``register(subparsers)`` function in a light
module (heavy imports happen inside the handlers), so ``darkread edge ...`` never imports the web
stack and ``darkread cloud ...`` never imports the USB stack.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from darkread import __version__
from darkread.errors import DarkreadError

# Modules that contribute sub-commands, in the order they appear in --help.
COMMAND_MODULES: tuple[str, ...] = (
    "darkread.edge.inspect",
    "darkread.edge.cli",
    "darkread.edge.sources.evk4.cli",
    "darkread.cloud.cli",
    "darkread.read",
    "darkread.models.synth.cli",
    "darkread.models.train.cli",
    "darkread.edge.calibrate.cli",
    "darkread.eval.cli",
    "darkread.gaze.cli",
)

DESCRIPTION = """\
darkread reads text in the dark with an event camera on eye-tracking glasses.

  source -> ring buffer -> fovea -> voxel grid -> U-Net -> uplink -> ingest -> stitch -> OCR

Start with `darkread read --demo` (the shipped sample recording, end to end), or
`darkread inspect RECORDING` to look at a recording.
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="darkread", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"darkread {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    parser.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name and name.startswith(exc.name):
                continue  # component not present in this installation
            raise
        module.register(subparsers)
    return parser


def configure_logging(verbose: int, quiet: bool) -> None:
    level = logging.WARNING if quiet else (logging.DEBUG if verbose > 1 else logging.INFO)
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)-7s %(name)s: %(message)s", stream=sys.stderr)


# What bad input and a failing environment raise: darkread's own errors, files and sockets
# (OSError), bad values and undecodable text or JSON (ValueError covers JSONDecodeError and
# UnicodeDecodeError). Exit 1 (or the DarkreadError's own ``exit_code``) with one line; anything
# else is a bug: exit 70 (EX_SOFTWARE).
USER_ERRORS: tuple[type[BaseException], ...] = (DarkreadError, OSError, ValueError)
EXIT_ERROR = 1
EXIT_USAGE = 2
EXIT_INTERNAL = 70
EXIT_INTERRUPTED = 130


def error_line(exc: BaseException) -> str:
    """One line for stderr: the message, or the exception's type when it has none."""
    message = " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, USER_ERRORS):
        return f"darkread: error: {message}"
    return f"darkread: internal error: {type(exc).__name__}: {message} (run with -vv for the traceback)"


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    configure_logging(args.verbose, args.quiet)
    handler = getattr(args, "func", None)
    if handler is None:
        parser.print_help()
        return EXIT_USAGE
    try:
        return int(handler(args) or 0)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except Exception as exc:  # one line for users; the traceback with -vv
        if args.verbose >= 2:
            raise
        print(error_line(exc), file=sys.stderr)
        if isinstance(exc, DarkreadError):
            return exc.exit_code
        return EXIT_ERROR if isinstance(exc, USER_ERRORS) else EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())

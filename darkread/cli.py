"""The single ``darkread`` command.

Each component adds its own sub-commands through a ``register(subparsers)`` function in a light
module (heavy imports happen inside the handlers), so ``darkread edge ...`` never imports the web
stack and ``darkread cloud ...`` never imports the USB stack.

The product's commands are listed here; the lab's (``synth``, ``train``, ``eval``, ``gaze``,
``bench``) come through the ``darkread.commands`` entry-point group, so this module never imports
the lab and an installation without it has the product's commands only.
"""

from __future__ import annotations

import argparse
import difflib
import importlib
import logging
import sys
from collections.abc import Callable, Iterator, Sequence
from importlib.metadata import entry_points

from darkread import __version__
from darkread.core.errors import DarkreadError

# The product's modules that contribute sub-commands, in the order they appear in --help.
COMMAND_MODULES: tuple[str, ...] = (
    "darkread.read",
    "darkread.edge.inspect",
    "darkread.edge.cli",
    "darkread.edge.sources.evk4.cli",
    "darkread.cloud.cli",
    "darkread.edge.calibrate.cli",
)
# Where other installed parts (the lab) register theirs: ``name = "module:register"``.
COMMAND_GROUP = "darkread.commands"

Register = Callable[[argparse._SubParsersAction], None]

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
    for register in registrations():
        register(subparsers)
    return parser


def registrations() -> Iterator[Register]:
    """Each part's ``register``: the product's modules, then the entry points of ``COMMAND_GROUP``."""
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name and name.startswith(exc.name):
                continue  # component not present in this installation
            raise
        yield module.register
    for entry in sorted(entry_points(group=COMMAND_GROUP), key=lambda e: e.name):
        try:
            yield entry.load()
        except ModuleNotFoundError as exc:  # a part whose extra is not installed here: its commands are absent
            logging.getLogger(__name__).debug("commands of %s not available: %s", entry.value, exc)


def configure_logging(verbose: int, quiet: bool) -> None:
    level = logging.WARNING if quiet else (logging.DEBUG if verbose > 1 else logging.INFO)
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)-7s %(name)s: %(message)s", stream=sys.stderr)
    # httpx logs every request at INFO (darkread read asks its own cloud): only with -vv
    logging.getLogger("httpx").setLevel(level if verbose > 1 else max(level, logging.WARNING))


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


def command_parser(parser: argparse.ArgumentParser, argv: Sequence[str]) -> argparse.ArgumentParser:
    """The (sub-)command's own parser that ``argv`` names, e.g. ``darkread edge run``'s."""
    current = parser
    for token in argv:
        commands = next((a for a in current._actions if isinstance(a, argparse._SubParsersAction)), None)
        if commands is None:
            break
        if token in commands.choices:
            current = commands.choices[token]
    return current


def parse(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> argparse.Namespace:
    """Parse ``argv``; an unknown option is reported with the usage of the command it was given to
    (argparse itself reports it with the top-level usage)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        command = command_parser(parser, argv)
        known = [option for action in command._actions for option in action.option_strings]
        options = [word.split("=", 1)[0] for word in unknown if word.startswith("-")]
        near = difflib.get_close_matches(options[0], known, n=1) if options else []
        hint = f" (did you mean {near[0]}?)" if near else f" (see {command.prog} --help)"
        command.error(f"unrecognized arguments: {' '.join(unknown)}{hint}")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parse(parser, argv)
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

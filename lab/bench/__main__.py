"""``python -m darkread.lab.bench``: the same as ``darkread bench``."""

from __future__ import annotations

import argparse
import logging
import sys

from darkread.lab.bench.cli import DESCRIPTION, add_arguments, run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m darkread.lab.bench", description=DESCRIPTION)
    add_arguments(parser)
    logging.basicConfig(level=logging.WARNING)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())

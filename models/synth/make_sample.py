"""Regenerate the sample recording shipped in ``darkread/data/sample_recording``.

    python -m darkread.models.synth.make_sample [OUT]

A short synthetic reading session (100 lux, paragraph text, 3 lines, x-height 10 px, resting head)
small enough to ship in the repository, with its ``text.txt`` so ``darkread read`` can score itself.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from darkread.core.paths import SAMPLE_RECORDING
from darkread.models.synth.recording import RecordingSpec, write_recording

SAMPLE_SPEC = RecordingSpec(
    lux=100.0,
    motion="still",
    kind="paragraph",
    seconds=3.0,
    seed=22,
    font="DejaVu Sans",
    xheight_px=10.0,
    n_lines=3,
    line_chars=20,
    description="synthetic reading session (darkread sample, made by darkread.models.synth.make_sample)",
)


def default_out() -> Path:

    return SAMPLE_RECORDING


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", nargs="?", default=None, help="output folder (default: the shipped sample)")
    args = parser.parse_args(argv)
    out = Path(args.out) if args.out else default_out()
    if out.exists():
        shutil.rmtree(out)
    meta = write_recording(out, SAMPLE_SPEC)
    size = sum(p.stat().st_size for p in out.iterdir())
    print(f"{out}: {meta['event_count']} events, {size / 1e6:.1f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

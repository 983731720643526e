"""Figures for the docs: training samples at several light levels.

    python -m darkread.lab.synth.figures docs/synth_samples.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from darkread.models.synth.session import SessionSpec
from darkread.models.synth.shards import make_samples

LUX_LEVELS = (1000.0, 30.0, 5.0)


def samples_figure(out: str | Path, seeds: tuple[int, ...] = (11, 23, 37), motion: str = "normal") -> Path:
    """Rows: windows; columns: voxel sum and target at each lux (same page, window and time)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = ("paragraph", "words", "letters")
    fig, axes = plt.subplots(len(seeds), 2 * len(LUX_LEVELS), figsize=(4.2 * len(LUX_LEVELS), 1.35 * len(seeds) + 0.6))
    axes = np.atleast_2d(axes)
    for r, seed in enumerate(seeds):
        spec = SessionSpec(duration_s=4.0, motion=motion, kind=kinds[r % len(kinds)], xheight_px=(10.0, 8.0, 13.0)[r % 3])
        for c, lux in enumerate(LUX_LEVELS):
            voxels, targets, metas = make_samples(spec, seed, 1, lux=lux)
            acc = voxels[0].astype(np.float32).sum(axis=0)
            ax_v, ax_t = axes[r, 2 * c], axes[r, 2 * c + 1]
            ax_v.imshow(acc, cmap="gray", vmin=-3, vmax=3, interpolation="nearest")
            ax_t.imshow(1 - targets[0], cmap="gray", vmin=0, vmax=1, interpolation="nearest")
            m = metas[0]
            ax_v.set_title(f"{lux:g} lux, voxel sum ({m.font}, x-height {m.xheight_px:.0f} px)", fontsize=6)
            ax_t.set_title("target (ink = black)", fontsize=7)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"synthetic training samples ({motion} motion): last 1600 foveated events summed over 4 bins; "
                 "same page, window and time at each light level", fontsize=8)
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", nargs="?", default="docs/synth_samples.png")
    args = parser.parse_args(argv)
    print(samples_figure(args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

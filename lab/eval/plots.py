"""The report's figures (matplotlib, headless): CER against light, size and motion, the OCR
engines side by side, and example pages next to the RGB snapshot of the same scene."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from darkread.lab.eval.aggregate import backend_names, group_by, mean
from darkread.lab.eval.results import RecordingResult
from darkread.lab.eval.tables import pct

SYSTEMS: tuple[tuple[str, str], ...] = (("darkread", "darkread (event camera)"), ("rgb", "RGB snapshot baseline"))


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _lux_axis(ax: Any, levels: list[float]) -> None:
    """Log scale, darker to the right, a tick at every light level of the suite."""
    ax.set_xscale("log")
    if levels:
        ax.set_xticks(levels, [f"{v:g}" for v in levels])
        ax.minorticks_off()
    ax.invert_xaxis()


Series = tuple[str, Sequence[RecordingResult], str]  # legend label, recordings, system ("darkread" or "rgb")


def plot_cer_vs(results: Sequence[RecordingResult], key: str, path: str | Path, *, xlabel: str, logx: bool = False,
                title: str = "", series: Sequence[Series] | None = None) -> Path:
    """Mean CER per value of ``key`` for darkread and the RGB baseline (or the given ``series``, e.g.
    darkread in two edge modes), each recording as a faint dot."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=120)
    lines = series if series is not None else [(label, results, system) for system, label in SYSTEMS]
    colours, markers = ("tab:blue", "tab:orange", "tab:green", "tab:red"), ("o", "s", "^", "D")
    for (label, members, system), colour, marker in zip(lines, colours, markers):
        xs, ys = [], []
        for value, group in group_by(members, key).items():
            m = mean(r.rate(system) for r in group)
            if value is not None and m is not None:
                xs.append(float(value))
                ys.append(m)
            pts = [(float(value), r.rate(system)) for r in group if value is not None and r.rate(system) is not None]
            if pts:
                ax.scatter(*zip(*pts), color=colour, alpha=0.25, s=14, marker=marker)
        if xs:
            ax.plot(xs, ys, marker=marker, color=colour, label=label)
    if logx:
        _lux_axis(ax, [float(v) for v in group_by(results, key) if v is not None])
    ax.set_xlabel(xlabel)
    ax.set_ylabel("character error rate (mean; dots: recordings)")
    ax.set_ylim(-0.03, 1.05)
    ax.yaxis.set_major_formatter(lambda v, _: f"{v:.0%}")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_cer_vs_lux_by_motion(results: Sequence[RecordingResult], path: str | Path) -> Path:
    """Two panels (darkread, RGB snapshot): mean CER vs lux, one line per motion level."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.6), dpi=120, sharey=True)
    colours = {"still": "tab:green", "normal": "tab:blue", "walking": "tab:red"}
    for ax, (system, label) in zip(axes, SYSTEMS):
        for motion, group in group_by(results, "motion").items():
            points = [(float(lux), mean(r.rate(system) for r in members))
                      for lux, members in group_by(group, "lux").items() if lux is not None]
            points = [(x, y) for x, y in points if y is not None]
            if points:
                ax.plot(*zip(*points), marker="o", label=str(motion), color=colours.get(str(motion)))
        _lux_axis(ax, [float(v) for v in group_by(results, "lux") if v is not None])
        ax.set_xlabel("illuminance at the page (lux, log scale)")
        ax.set_title(label, fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.yaxis.set_major_formatter(lambda v, _: f"{v:.0%}")
    axes[0].set_ylabel("character error rate (mean)")
    axes[0].set_ylim(-0.03, 1.05)
    axes[1].legend(title="motion", loc="best")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_backends(results: Sequence[RecordingResult], path: str | Path) -> Path | None:
    """Grouped bars: mean CER of each OCR engine on the stitched pages, by text kind."""
    names = backend_names(results)
    if not names:
        return None
    plt = _pyplot()
    groups = group_by(results, "kind")
    fig, ax = plt.subplots(figsize=(6.4, 3.8), dpi=120)
    width = 0.8 / len(names)
    for i, name in enumerate(names):
        values = [mean(r.backend_rate(name) for r in group) for group in groups.values()]
        xs = [k + (i - (len(names) - 1) / 2) * width for k in range(len(groups))]
        ax.bar(xs, [v if v is not None else 0 for v in values], width, label=name)
    ax.set_xticks(range(len(groups)), [str(k) for k in groups])
    ax.set_ylabel("character error rate (mean)")
    ax.yaxis.set_major_formatter(lambda v, _: f"{v:.0%}")
    ax.set_ylim(0, 1.05)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend()
    ax.set_title("OCR engines on the same stitched darkread pages", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_examples(
    results: Sequence[RecordingResult], path: str | Path, *, motion: str = "normal", kind: str = "paragraph"
) -> Path | None:
    """One row per lux level: the RGB snapshot crop next to the page darkread stitched (same scene);
    a ``kind`` recording with ``motion`` where there is one."""
    chosen = []
    for _lux, group in sorted(group_by(results, "lux").items(), key=lambda kv: -float(kv[0] or 0)):
        pick = ([r for r in group if r.motion == motion and r.kind == kind]
                or [r for r in group if r.motion == motion] or group)
        r = pick[0]
        crop, page = r.rgb.crop_png if r.rgb else None, r.darkread.page_png if r.darkread else None
        if crop and page and Path(crop).is_file() and Path(page).is_file():
            chosen.append((r, crop, page))
    if not chosen:
        return None
    plt = _pyplot()
    from PIL import Image

    fig, axes = plt.subplots(len(chosen), 2, figsize=(8.0, 1.7 * len(chosen)), dpi=120, squeeze=False)
    for row, (r, crop, page) in zip(axes, chosen):
        for ax, file, title in ((row[0], crop, f"RGB snapshot, CER {pct(r.rate('rgb'))}"),
                                (row[1], page, f"darkread page, CER {pct(r.rate('darkread'))}")):
            with Image.open(file) as image:
                ax.imshow(image.convert("L"), cmap="gray", vmin=0, vmax=255)
            ax.set_title(f"{r.lux or 0:g} lux, {r.motion}: {title}", fontsize=8)
            ax.set_axis_off()
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path

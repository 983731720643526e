"""Training data: synthetic shards -> shuffled, augmented torch batches.

A shard ``shard-NNNNN.npz`` holds ``voxels`` float16 [n,4,100,200], ``targets`` packed bits
(``darkread.core.mask_bits.pack_rows``, [n,100,25]), optionally ``ignore`` (packed the same way: pixels
no loss or score may count, e.g. the markers an annotated window sees; a shard without it, every
synthetic one, has all pixels valid), ``target_shape`` and per-sample metadata
(``models.synth.shards.METADATA_KEYS``: lux, x-height, motion, font, kind, seed, window origin,
window end time, event count); ``models/synth/shards.py`` writes them, this module reads them. Shards are streamed a few
at a time so a 30 k-sample set (~5 GB as float16) never has to sit in memory at once.

Augmentation (all exact for the physics of the voxel grid, none changes glyph shapes):

* **time reversal**: reverse the bin order and negate. The E2VID voxel grid maps t -> B-1-t* under
  reversal and a reversed scene swaps ON/OFF, and both commute with the non-zero normalisation,
  so this is exactly the same page seen moving the other way: same target.
* **small shifts** (a few pixels, zero fill): the fovea is centred on noisy gaze, so text sits
  anywhere in the window.
* **no mirror flips**: mirrored glyphs never occur on a page, and at 5 lux the network has to
  fill in strokes from a prior over real letter shapes; mirrored samples would blur that prior.
  Neither a polarity-only flip (that is white ink on black paper, the opposite of the target).
"""

from __future__ import annotations

import itertools
import logging
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darkread.core.mask_bits import unpack_rows
from darkread.models.synth.shards import METADATA_KEYS

log = logging.getLogger(__name__)

IGNORE_LABEL = 255  # in a label array (``labels``): a pixel no loss counts


@dataclass
class Shard:
    """One shard in memory: voxels float16 [n,4,H,W], targets uint8 [n,H,W] (1 = ink), metadata,
    and ``ignore`` uint8 [n,H,W] (1 = not a training pixel) or None when every pixel is valid."""

    voxels: np.ndarray
    targets: np.ndarray
    meta: dict[str, np.ndarray]
    ignore: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.voxels.shape[0])

    def select(self, index: np.ndarray) -> Shard:
        return Shard(self.voxels[index], self.targets[index], {k: v[index] for k, v in self.meta.items()},
                     None if self.ignore is None else self.ignore[index])

    def ignore_or_none(self) -> np.ndarray:
        """``ignore`` with every pixel valid (zeros) when the shard has none."""
        return np.zeros_like(self.targets) if self.ignore is None else self.ignore


def concat_shards(parts: Sequence[Shard], meta_keys: Sequence[str] = ()) -> Shard:
    """Shards one after the other; ``ignore`` is kept when any part has one (the others: all valid)."""
    ignore = np.concatenate([p.ignore_or_none() for p in parts]) if any(p.ignore is not None for p in parts) else None
    return Shard(np.concatenate([p.voxels for p in parts]), np.concatenate([p.targets for p in parts]),
                 {k: np.concatenate([p.meta[k] for p in parts]) for k in meta_keys}, ignore)


def labels(targets: np.ndarray, ignore: np.ndarray | None) -> np.ndarray:
    """Targets (0/1) with ignored pixels set to ``IGNORE_LABEL``: one array that shifts and crops
    (``augment``, ``random_crop``) move together with the voxels; ``split_labels`` undoes it."""
    return targets if ignore is None else np.where(ignore != 0, np.uint8(IGNORE_LABEL), targets).astype(np.uint8)


def split_labels(labels_: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(targets 0/1, valid 0/1) of a label array."""
    valid = labels_ != IGNORE_LABEL
    return (labels_ == 1).astype(np.uint8), valid.astype(np.uint8)


def shard_paths(root: str | Path | Sequence[str | Path]) -> list[Path]:
    """Shards of a dataset directory (sorted), or a single shard file; several roots: all their shards
    (a training mix, e.g. a standard set and a low-light one), interleaved so the first shards,
    where the held-out validation samples come from, hold some of every set."""
    if not isinstance(root, (str, Path)):
        per_root = [shard_paths(r) for r in root]
        if not per_root:
            raise FileNotFoundError("no training set given")
        return [p for group in itertools.zip_longest(*per_root) for p in group if p is not None]
    path = Path(root)
    if path.is_file():
        return [path]
    paths = sorted(p for p in path.glob("shard-*.npz") if p.stem[len("shard-") :].isdigit())  # not *.tmp.npz
    if not paths:
        raise FileNotFoundError(f"no shard-*.npz files in {path}; make a dataset with `darkread synth ...`")
    return paths


SHARD_READ_ERRORS = (zipfile.BadZipFile, EOFError, KeyError, ValueError)  # what a truncated or foreign shard raises


def unreadable_shard(path: str | Path, exc: Exception) -> ValueError:
    return ValueError(f"{path}: not a readable training shard ({exc}); make it again with `darkread synth dataset` "
                      "or `darkread train annotate`")


def load_shard(path: str | Path) -> Shard:
    """One shard file; a truncated or foreign file is a ``ValueError`` naming it (one line for the CLI)."""
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:  # (np.load(path) leaks its file on a damaged zip)
            voxels = data["voxels"]
            packed = data["targets"]
            target_shape = tuple(int(v) for v in data["target_shape"]) if "target_shape" in data else voxels.shape[-2:]
            targets = unpack_rows(packed, target_shape[-1]) if packed.shape[-1] != target_shape[-1] else packed
            meta = {key: data[key] for key in METADATA_KEYS if key in data}
            ignore = unpack_rows(data["ignore"], target_shape[-1]) if "ignore" in data else None
    except SHARD_READ_ERRORS as exc:
        raise unreadable_shard(path, exc) from exc
    return Shard(voxels=voxels, targets=targets.astype(np.uint8), meta=meta, ignore=ignore)


def count_samples(root: str | Path) -> int:
    """How many samples a dataset holds, from each shard's small packed targets (the voxels stay unread)."""
    total = 0
    for path in shard_paths(root):
        try:
            with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
                total += int(data["targets"].shape[0])
        except SHARD_READ_ERRORS as exc:
            raise unreadable_shard(path, exc) from exc
    return total


def iter_shards(root: str | Path) -> Iterator[Shard]:
    """The shards of a dataset one at a time (memory stays at one shard)."""
    for path in shard_paths(root):
        yield load_shard(path)


def load_dataset(root: str | Path, limit: int | None = None) -> Shard:
    """Every shard of a dataset concatenated (for evaluation-sized sets), at most ``limit`` samples."""
    parts: list[Shard] = []
    total = 0
    for path in shard_paths(root):
        shard = load_shard(path)
        parts.append(shard)
        total += len(shard)
        if limit is not None and total >= limit:
            break
    keys = set.intersection(*(set(p.meta) for p in parts)) if parts else set()
    merged = concat_shards(parts, sorted(keys))
    return merged if limit is None else merged.select(np.arange(min(limit, len(merged))))


def is_validation_seed(seeds: np.ndarray, every: int = 20) -> np.ndarray:
    """The held-out split by seed: deterministic, independent of shard order and size."""
    mixed = (seeds.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(40)
    return (mixed % np.uint64(every)) == 0


def split_mask(shard: Shard, validation: bool, every: int = 20) -> np.ndarray:
    seeds = shard.meta.get("seed")
    if seeds is None:
        seeds = np.arange(len(shard))
    held_out = is_validation_seed(np.asarray(seeds), every)
    return held_out if validation else ~held_out


def augment(voxels: np.ndarray, targets: np.ndarray, rng: np.random.Generator, max_shift: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Time reversal and small shifts for a batch (float32 [n,4,H,W], uint8 [n,H,W]); returns new arrays."""
    voxels = voxels.copy()
    targets = targets.copy()
    reverse = rng.random(len(voxels)) < 0.5
    voxels[reverse] = -voxels[reverse][:, ::-1]
    if max_shift > 0:
        for i in range(len(voxels)):
            dy, dx = rng.integers(-max_shift, max_shift + 1, size=2)
            voxels[i] = _shift(voxels[i], int(dy), int(dx))
            targets[i] = _shift(targets[i], int(dy), int(dx))
    return voxels, targets


def random_crop(voxels: np.ndarray, targets: np.ndarray, size: tuple[int, int], rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One random ``size`` crop per sample. Training on crops costs a third of the CPU per sample;
    the network is fully convolutional, so it still runs on the whole 100x200 window."""
    h, w = size
    n, full_h, full_w = targets.shape
    if h >= full_h and w >= full_w:
        return voxels, targets
    ys = rng.integers(0, full_h - h + 1, size=n)
    xs = rng.integers(0, full_w - w + 1, size=n)
    out_v = np.stack([voxels[i, :, y : y + h, x : x + w] for i, (y, x) in enumerate(zip(ys, xs))])
    out_t = np.stack([targets[i, y : y + h, x : x + w] for i, (y, x) in enumerate(zip(ys, xs))])
    return out_v, out_t


def _shift(array: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """Shift the last two axes with zero fill (not wrap: text must not reappear on the other side)."""
    out = np.zeros_like(array)
    h, w = array.shape[-2:]
    ys, yd = (slice(0, h - dy), slice(dy, h)) if dy >= 0 else (slice(-dy, h), slice(0, h + dy))
    xs, xd = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
    out[..., yd, xd] = array[..., ys, xs]
    return out


def iterate_batches(
    paths: Sequence[Path],
    batch_size: int,
    rng: np.random.Generator,
    *,
    validation: bool = False,
    shards_in_memory: int = 2,
    augmentation: bool = True,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """One pass over the training (or held-out) part of ``paths``: float32 voxels, uint8 targets.

    Shards are visited in random order, ``shards_in_memory`` at a time, and samples are shuffled
    across the shards in memory.
    """
    order = list(rng.permutation(len(paths)))
    for start in range(0, len(order), shards_in_memory):
        group = [load_shard(paths[i]) for i in order[start : start + shards_in_memory]]
        voxels = np.concatenate([g.voxels[split_mask(g, validation)] for g in group])
        targets = np.concatenate([g.targets[split_mask(g, validation)] for g in group])
        index = rng.permutation(len(voxels)) if not validation else np.arange(len(voxels))
        for b in range(0, len(index), batch_size):
            take = index[b : b + batch_size]
            x = voxels[take].astype(np.float32)
            y = targets[take]
            if augmentation and not validation:
                x, y = augment(x, y, rng)
            yield x, y

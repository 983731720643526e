"""Reading training shards written by ``darkread synth dataset``.

A dataset folder holds ``dataset.json`` and ``shard-NNNNN.npz`` files; each shard has ``voxels``
(float16 [n, 4, 100, 200]), ``targets`` (np.packbits of the uint8 ink mask on the last axis,
[n, 100, 25]) with ``target_shape``, and per-sample ``lux``, ``xheight_px``, ``motion``, ``font``,
``kind``, ``seed``, ``window_origin``, ``t_end_us``, ``n_events``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

META_KEYS = ("lux", "xheight_px", "motion", "font", "kind", "seed", "window_origin", "t_end_us", "n_events")


@dataclass
class Shard:
    voxels: np.ndarray  # float16 [n, 4, 100, 200]
    targets: np.ndarray  # uint8 [n, 100, 200], 1 = ink
    meta: dict[str, np.ndarray]

    def __len__(self) -> int:
        return int(self.voxels.shape[0])


def read_manifest(path: str | Path) -> dict:
    manifest = Path(path) / "dataset.json"
    if not manifest.is_file():
        raise FileNotFoundError(f"{manifest} not found; is {path} a folder made by `darkread synth dataset`?")
    return json.loads(manifest.read_text())


def shard_paths(path: str | Path) -> list[Path]:
    """Shard files of a dataset folder (those the manifest lists, or every shard-*.npz if it has none)."""
    root = Path(path)
    if (root / "dataset.json").is_file():
        names = read_manifest(root).get("shards", [])
        paths = [root / n for n in names if (root / n).is_file()]
        if paths:
            return paths
    paths = sorted(root.glob("shard-*.npz"))
    if not paths:
        raise FileNotFoundError(f"no shard-*.npz files in {root}")
    return paths


def load_shard(path: str | Path) -> Shard:
    with np.load(path, allow_pickle=False) as z:
        shape = tuple(int(s) for s in z["target_shape"])
        targets = np.unpackbits(z["targets"], axis=-1, count=shape[-1]).astype(np.uint8)
        meta = {k: z[k] for k in META_KEYS if k in z.files}
        return Shard(voxels=z["voxels"], targets=targets, meta=meta)


def iter_shards(path: str | Path) -> Iterator[Shard]:
    """Shards of a dataset folder, one at a time (memory stays at one shard)."""
    for p in shard_paths(path):
        yield load_shard(p)


def load_dataset(path: str | Path, *, max_samples: int | None = None) -> Shard:
    """All shards concatenated (float16 voxels: ~160 kB per sample in memory)."""
    voxels, targets, metas = [], [], []
    n = 0
    for shard in iter_shards(path):
        voxels.append(shard.voxels)
        targets.append(shard.targets)
        metas.append(shard.meta)
        n += len(shard)
        if max_samples is not None and n >= max_samples:
            break
    meta = {k: np.concatenate([m[k] for m in metas]) for k in metas[0]}
    out = Shard(np.concatenate(voxels), np.concatenate(targets), meta)
    if max_samples is not None:
        out = Shard(out.voxels[:max_samples], out.targets[:max_samples], {k: v[:max_samples] for k, v in meta.items()})
    return out

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from darkread.models.train.fit import FitConfig, fit, load_model
from darkread.models.train.net import NetConfig


def _tiny_config(**overrides) -> FitConfig:
    base = dict(
        batch_size=4, lr=5e-3, warmup_steps=1, time_budget_s=60, max_epochs=2, threads=1,
        validation_samples=8, checkpoint_every_s=1e9, crop=None,
        net=NetConfig(widths=(4, 8, 16, 16), blocks=(1, 1, 1)).to_dict(),
    )
    base.update(overrides)
    return FitConfig(**base)


def test_a_few_steps_reduce_the_loss(fake_dataset, tmp_path: Path) -> None:
    root = fake_dataset(shards=1, per_shard=40)
    losses: list[float] = []
    fit(root, tmp_path / "run", _tiny_config(max_epochs=3), progress=False, on_step=lambda s, l: losses.append(l))
    assert len(losses) >= 20
    assert np.mean(losses[-4:]) < 0.8 * np.mean(losses[:4])


def test_checkpoints_resume_where_they_stopped(fake_dataset, tmp_path: Path) -> None:
    root = fake_dataset(shards=1, per_shard=16)
    out = tmp_path / "run"
    first = fit(root, out, _tiny_config(max_epochs=1), progress=False)
    assert (out / "last.pt").exists() and (out / "best.pt").exists()
    second = fit(root, out, _tiny_config(max_epochs=2), progress=False)
    assert second["steps"] > first["steps"] and second["epochs"] == 2
    history = json.loads((out / "history.json").read_text())["history"]
    assert [h["epoch"] for h in history] == [1.0, 2.0]
    model = load_model(out / "best.pt")
    assert not model.training

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
    fit(root, tmp_path / "run", _tiny_config(max_epochs=3), progress=False, on_step=lambda _step, loss: losses.append(loss))
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


def test_several_training_sets_are_interleaved_shard_by_shard(fake_dataset) -> None:
    from darkread.models.train.data import shard_paths

    standard, low = fake_dataset(shards=3, name="standard"), fake_dataset(shards=1, name="low")
    paths = shard_paths([standard, low])
    assert [p.parent.name for p in paths] == ["standard", "low", "standard", "standard"]
    assert shard_paths([standard]) == shard_paths(standard)


def test_a_fit_from_an_exported_network_starts_where_it_left_off(fake_dataset, tmp_path: Path) -> None:
    """--init model.onnx: the folded BatchNorms stay frozen, so the first validation equals the ONNX net's."""
    import torch

    from darkread.models.train.data import load_dataset
    from darkread.models.train.export import export_onnx
    from darkread.models.train.fit import evaluate_model, load_initial_weights
    from darkread.models.train.net import BinaryUNet

    net = NetConfig(widths=(4, 8, 16, 16), blocks=(1, 1, 1))
    torch.manual_seed(3)
    model = BinaryUNet(net).eval()
    for module in model.modules():  # non-trivial BatchNorm statistics, as a trained net has
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_mean.uniform_(-0.2, 0.2)
            module.running_var.uniform_(0.5, 2.0)
    onnx_path = export_onnx(model, tmp_path / "start.onnx")
    root = fake_dataset(shards=1, per_shard=16)
    data = load_dataset(root)
    expected = evaluate_model(model, data.voxels, data.targets)
    started = load_initial_weights(onnx_path, net)
    assert abs(evaluate_model(started, data.voxels, data.targets)["bce"] - expected["bce"]) < 1e-4
    summary = fit(root, tmp_path / "run", _tiny_config(lr=1e-4, freeze_batchnorm=True, net=net.to_dict()),
                  progress=False, init_checkpoint=onnx_path)
    assert summary["steps"] > 0
    tuned = load_model(tmp_path / "run" / "last.pt")
    bns = [m for m in tuned.modules() if isinstance(m, torch.nn.BatchNorm2d)]
    assert all(float(m.running_mean.abs().max()) == 0.0 for m in bns)  # frozen: still the identity of a folded net

    # resumed without --init (a config that does not say frozen): the run stays frozen
    fit(root, tmp_path / "run", _tiny_config(lr=1e-4, max_epochs=3, net=net.to_dict()), progress=False)
    resumed = load_model(tmp_path / "run" / "last.pt")
    assert all(float(m.running_mean.abs().max()) == 0.0 for m in resumed.modules() if isinstance(m, torch.nn.BatchNorm2d))


def test_init_from_a_missing_file_is_one_clear_error(fake_dataset, tmp_path: Path) -> None:
    import pytest

    from darkread.models.train.fit import load_initial_weights

    with pytest.raises(FileNotFoundError, match="--init .*no such file"):
        load_initial_weights(tmp_path / "nope.onnx", NetConfig())
    text = tmp_path / "notes.pt"
    text.write_text("# not a checkpoint\n")
    truncated = tmp_path / "cut.pt"
    data = fake_dataset(shards=1, per_shard=8)
    fit(data, tmp_path / "whole", _tiny_config(max_epochs=1), progress=False)
    truncated.write_bytes((tmp_path / "whole" / "last.pt").read_bytes()[:300])
    for bad in (text, truncated):
        with pytest.raises(ValueError, match="not a training checkpoint"):
            load_initial_weights(bad, None)
    with pytest.raises(FileNotFoundError, match="--teacher .*no such file"):  # a teacher's path is named as one
        fit(data, tmp_path / "run", _tiny_config(teacher=str(tmp_path / "nope.onnx")), progress=False)


def test_distilling_a_teacher_brings_the_student_to_its_ink_probability(fake_dataset, tmp_path: Path) -> None:
    """--teacher: with the whole loss on the teacher, the student ends closer to what the teacher gives."""
    import torch

    from darkread.models.train.data import load_dataset
    from darkread.models.train.export import export_onnx
    from darkread.models.train.net import BinaryUNet

    net = NetConfig(widths=(4, 8, 16, 16), blocks=(1, 1, 1))
    torch.manual_seed(5)
    teacher = BinaryUNet(net).eval()
    teacher_path = export_onnx(teacher, tmp_path / "teacher.onnx")
    root = fake_dataset(shards=1, per_shard=40)
    x = torch.from_numpy(load_dataset(root).voxels[:16].astype(np.float32))

    def gap(model: BinaryUNet) -> float:
        with torch.no_grad():
            return float((torch.sigmoid(model.eval()(x)) - torch.sigmoid(teacher(x))).abs().mean())

    student_net = NetConfig(widths=(4, 8, 16, 16), blocks=(1, 1, 1), head="shuffle")
    torch.manual_seed(6)
    before = gap(BinaryUNet(student_net))
    config = _tiny_config(max_epochs=6, lr=1e-2, net=student_net.to_dict(), teacher=str(teacher_path), teacher_weight=1.0)
    torch.manual_seed(6)
    fit(root, tmp_path / "run", config, progress=False)
    assert gap(load_model(tmp_path / "run" / "last.pt")) < 0.5 * before

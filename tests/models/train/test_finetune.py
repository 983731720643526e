"""Fine-tuning from the shipped ONNX on annotated shards mixed with synthetic ones; the CLI's bad inputs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from darkread_cli import assert_one_error_line, darkread

from darkread.edge.reconstruct import Reconstructor
from darkread.models.train.data import Shard
from darkread.models.train.export import export_onnx
from darkread.models.train.finetune import FinetuneError, TuneConfig, finetune, lr_at, spread_indices, trainable_parameters, tune
from darkread.models.train.net import BinaryUNet

TINY = TuneConfig(steps=3, batch_size=4, warmup_steps=1, crop=(32, 64), monitor_windows=4, threads=1)


@pytest.fixture(scope="module")
def base_model(tmp_path_factory) -> Path:
    """A small-valued BinaryUNet as ONNX (the shipped file's architecture; independent of it being installed)."""
    import torch

    torch.manual_seed(0)
    return export_onnx(BinaryUNet().eval(), tmp_path_factory.mktemp("base") / "base.onnx")


def annotated_dir(root: Path, name: str, n: int, seed: int, shard_writer) -> Path:
    d = root / name
    d.mkdir()
    shard_writer(d / "shard-00000.npz", n, seed)
    return d


def test_finetune_on_a_tiny_annotated_shard_exports_a_loadable_onnx(tmp_path, base_model, shard_writer) -> None:
    ann = annotated_dir(tmp_path, "rec_annotated", 6, 0, shard_writer)
    syn = annotated_dir(tmp_path, "synthetic", 10, 1, shard_writer)
    summary = finetune([ann], base_model, tmp_path / "run", tmp_path / "tuned.onnx", cfg=TINY, synthetic=6, synthetic_dirs=[syn],
                       progress=False)
    assert summary["steps"] == 3 and summary["annotated_windows"] == 6 and summary["synthetic_windows"] == 6
    assert summary["batch"] == {"annotated": 2, "synthetic": 2}
    trip = summary["round_trip_max_logit_difference"]
    assert trip["shipped_onnx_to_torch"] < 1e-4 and trip["torch_to_exported_onnx"] < 1e-4
    voxels = np.random.default_rng(2).normal(size=(2, 4, 100, 200)).astype(np.float32)
    tuned, before = Reconstructor(tmp_path / "tuned.onnx", warmup=0), Reconstructor(base_model, warmup=0)
    assert tuned.logits(voxels).shape == (2, 100, 200)
    assert not np.allclose(tuned.logits(voxels), before.logits(voxels))  # the weights moved
    saved = json.loads((tmp_path / "run" / "finetune.json").read_text())
    assert saved["exported"] == str(tmp_path / "tuned.onnx") and (tmp_path / "run" / "tuned.pt").is_file()


def test_the_tuned_network_carries_its_base_networks_ink_temperature(tmp_path, base_model, shard_writer) -> None:
    """The edge reads a network without a stored temperature at the default; a tuned copy of the
    shipped network must be read as the shipped one is, or the comparison measures the edge."""
    import shutil

    from darkread.models.train.calibrate import store_ink_temperature

    ann = annotated_dir(tmp_path, "ann", 4, 4, shard_writer)
    unmarked = finetune([ann], base_model, tmp_path / "run0", tmp_path / "plain.onnx", cfg=TINY, synthetic=0, progress=False)
    assert unmarked["ink_temperature"] is None
    assert Reconstructor(tmp_path / "plain.onnx", warmup=0).temperature == Reconstructor(base_model, warmup=0).temperature
    marked = store_ink_temperature(shutil.copy(base_model, tmp_path / "base_t.onnx"), 0.8)
    summary = finetune([ann], marked, tmp_path / "run1", tmp_path / "tuned.onnx", cfg=TINY, synthetic=0, progress=False)
    assert summary["ink_temperature"] == 0.8
    assert Reconstructor(tmp_path / "tuned.onnx", warmup=0).temperature == 0.8


def test_no_annotated_windows_is_an_error(tmp_path, base_model) -> None:
    with pytest.raises(FinetuneError, match="no annotated windows"):
        finetune([], base_model, tmp_path / "run", cfg=TINY, synthetic=0, progress=False)


def test_the_anchor_keeps_the_synthetic_windows_answer_near_the_starting_network() -> None:
    """Tuned toward random synthetic targets, the anchored network's answer on those windows moves
    less from where it started than the unanchored one's; the annotated rows are not anchored."""
    import copy

    import torch

    rng = np.random.default_rng(5)

    def pool(n: int) -> Shard:
        return Shard(rng.normal(size=(n, 4, 32, 64)).astype(np.float16), (rng.random((n, 32, 64)) < 0.5).astype(np.uint8), {})

    annotated, synthetic = pool(4), pool(4)
    torch.manual_seed(0)
    start = BinaryUNet().eval()
    cfg = TuneConfig(lr=5e-3, steps=15, batch_size=4, warmup_steps=1, crop=None, max_shift=0, synthetic_share=0.5, threads=1)
    probe = torch.from_numpy(synthetic.voxels.astype(np.float32))
    with torch.no_grad():
        before = torch.sigmoid(start(probe))
    moved = {}
    for weight in (0.0, 5.0):
        model, anchor = copy.deepcopy(start), copy.deepcopy(start).eval()
        run = tune(model, annotated, synthetic, TuneConfig(**{**cfg.__dict__, "anchor_weight": weight}), anchor=anchor, progress=False)
        assert run["steps"] == 15
        with torch.no_grad():
            moved[weight] = float((torch.sigmoid(model(probe)) - before).abs().mean())
    assert moved[5.0] < 0.6 * moved[0.0], moved


def test_learning_rate_warms_up_then_decays() -> None:
    cfg = TuneConfig(lr=1e-3, warmup_steps=10)
    assert lr_at(0, cfg, 0.0) == pytest.approx(1e-4)
    assert lr_at(10, cfg, 0.0) == pytest.approx(1e-3)
    assert lr_at(10, cfg, 1.0) == pytest.approx(5e-5)


@pytest.mark.slow  # five CLI processes (torch import, an ONNX export): ~30 s idle, minutes on a loaded machine
def test_cli_finetune_runs_and_bad_inputs_fail_in_one_line(tmp_path, base_model, shard_writer) -> None:
    ann = annotated_dir(tmp_path, "ann", 4, 3, shard_writer)
    result = darkread("train", "finetune", "--annotated", str(ann), "--base", str(base_model), "--synthetic", "0", "--steps", "2",
                      "--batch-size", "2", "--run-dir", str(tmp_path / "run"), "--export", str(tmp_path / "t.onnx"), "--quiet")
    assert result.returncode == 0, result.stderr[-2000:]
    assert json.loads(result.stdout)["steps"] == 2 and (tmp_path / "t.onnx").is_file()
    assert_one_error_line(darkread("train", "finetune"), "nothing to tune on")
    assert_one_error_line(darkread("train", "finetune", "--annotated", str(tmp_path / "nope")), "no such directory")
    assert_one_error_line(darkread("train", "finetune", "--annotated", str(ann), "--synthetic-share", "1.5"), "--synthetic-share")
    assert_one_error_line(darkread("train", "finetune", "--annotated", str(ann), "--synthetic-dir", str(ann), str(tmp_path / "gone")),
                          "gone: no such directory")
    usage = darkread("train", "finetune", "--annotated", str(ann), "--synthetic", "most")
    assert usage.returncode == 2 and "a count or 'all'" in usage.stderr and "Traceback" not in usage.stderr
    assert_one_error_line(darkread("train", "finetune", "--annotated", str(ann), "--anchor", "-1"), "--anchor")
    assert_one_error_line(darkread("train", "finetune", "--annotated", str(ann), "--base", str(base_model), "--synthetic", "0",
                                   "--steps", "1", "--batch-size", "2", "--run-dir", str(tmp_path / "run2"),
                                   "--train-only", "stem,decoder", "--quiet"), "--train-only decoder")
    (tmp_path / "empty").mkdir()  # refused before the windows are loaded: an empty directory is not what it names
    assert_one_error_line(darkread("train", "finetune", "--annotated", str(tmp_path / "empty"), "--base", str(base_model),
                                   "--train-only", "decoder", "--quiet"), "--train-only decoder")
    assert_one_error_line(darkread("train", "compare", str(ann), "--model", str(tmp_path / "none.onnx")), "no such model file")


def test_the_monitored_windows_come_from_every_recording_not_the_first() -> None:
    """Annotated windows come recording after recording: the monitor spreads its pick over all of them."""
    picked = spread_indices(2072, 96)
    assert len(picked) == 96 and picked[0] == 0 and picked[-1] == 2071
    assert np.all(np.diff(picked) >= 21)  # every ~22nd window, not windows 0..95
    assert spread_indices(5, 96).tolist() == [0, 1, 2, 3, 4]


def test_train_only_tunes_the_named_parts_and_leaves_the_rest_as_they_were(shard_writer, tmp_path) -> None:
    import torch

    from darkread.models.train.data import load_shard

    torch.manual_seed(0)
    model = BinaryUNet()
    before = {k: v.clone() for k, v in model.state_dict().items()}
    shard_writer(tmp_path / "shard-00000.npz", 8, 0)
    pool = load_shard(tmp_path / "shard-00000.npz")
    cfg = TuneConfig(steps=3, batch_size=4, warmup_steps=1, crop=(32, 64), monitor_windows=4, threads=1, lr=1e-2,
                     train_only=("stem", "down1"))
    tune(model, pool, pool, cfg)
    after = model.state_dict()
    moved = {k.split(".")[0] for k in before if not torch.equal(before[k], after[k])}
    assert moved and moved <= {"stem", "down1"}, moved
    assert len(trainable_parameters(BinaryUNet(), ())) == len(list(BinaryUNet().parameters()))
    with pytest.raises(ValueError, match="--train-only decoder: no such part"):
        trainable_parameters(BinaryUNet(), ("stem", "decoder"))


def test_synthetic_windows_come_from_several_directories_in_turn(tmp_path, shard_writer) -> None:
    """Random crops first, then windows of simulated reading, until as many as asked are loaded."""
    from darkread.models.train.data import load_dataset
    from darkread.models.train.finetune import synthetic_windows

    crops = annotated_dir(tmp_path, "crops", 5, 1, shard_writer)
    reading = annotated_dir(tmp_path, "reading", 6, 2, shard_writer)
    both = synthetic_windows(8, [crops, reading], progress=False)
    assert len(both) == 8
    np.testing.assert_array_equal(both.targets[:5], load_dataset(crops).targets)
    np.testing.assert_array_equal(both.targets[5:], load_dataset(reading).targets[:3])
    assert len(synthetic_windows(4, [crops, reading], progress=False)) == 4  # the first directory alone suffices
    assert len(synthetic_windows(50, [crops, reading], progress=False)) == 11  # all there are


def test_synthetic_all_takes_every_window_of_the_directories(tmp_path, base_model, shard_writer) -> None:
    from darkread.models.train.data import count_samples

    ann = annotated_dir(tmp_path, "ann", 4, 0, shard_writer)
    crops = annotated_dir(tmp_path, "crops", 7, 1, shard_writer)
    reading = annotated_dir(tmp_path, "reading", 5, 2, shard_writer)
    assert count_samples(crops) + count_samples(reading) == 12
    summary = finetune([ann], base_model, tmp_path / "run", cfg=TINY, synthetic=None, synthetic_dirs=[crops, reading],
                       progress=False)
    assert summary["synthetic_windows"] == 12 - TINY.monitor_windows  # all of them, the monitor's first
    with pytest.raises(FinetuneError, match="--synthetic all"):
        finetune([ann], base_model, tmp_path / "run2", cfg=TINY, synthetic=None, progress=False)
    (crops / "shard-00001.npz").write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(ValueError, match="shard-00001.npz: not a readable training shard"):
        count_samples(crops)

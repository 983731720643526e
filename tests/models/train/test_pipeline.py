from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from darkread.edge.reconstruct import Reconstructor
from darkread.models.train.fit import FitConfig, fit
from darkread.models.train.net import NetConfig
from darkread.models.train.pipeline import finish


@pytest.mark.slow
def test_fit_export_evaluate_and_card_on_a_tiny_dataset(fake_dataset, tmp_path: Path) -> None:
    train = fake_dataset(shards=1, per_shard=40, name="train")
    val = fake_dataset(shards=1, per_shard=10, name="val")
    run = tmp_path / "run"
    config = FitConfig(batch_size=8, warmup_steps=1, max_epochs=1, threads=1, validation_samples=8,
                       net=NetConfig(widths=(4, 8, 16, 16), blocks=(1, 1, 1)).to_dict())
    fit(train, run, config, progress=False)
    models = tmp_path / "models"
    figure = tmp_path / "samples.png"
    info = finish(run, train, val, models_dir=models, eval_limit=10, figure=figure)
    assert (models / "binary_unet.onnx").is_file() and (models / "binary_unet_int8.onnx").is_file()
    assert Reconstructor(models / "binary_unet_int8.onnx", warmup=0)(np.zeros((4, 100, 200), np.float32)).shape == (100, 200)
    report = info["report"]
    assert report["samples"] == 10
    assert [row["group"].split()[0] for row in report["by_lux"]] == ["1000", "100", "30", "10", "5"]
    assert all(0 <= row["fp32_f1"] <= 1 and 0 <= row["baseline_f1"] <= 1 for row in report["by_lux"])
    card = (models / "MODEL_CARD.md").read_text()
    assert "| 30 (17-55) | 2 |" in card and "naive baseline" in card
    assert figure.stat().st_size > 1000
    assert json.loads((run / "evaluation.json").read_text())["latency"]["fp32_ms"] > 0


def test_cli_registers_train_steps_without_importing_torch() -> None:
    script = (
        "import sys; sys.modules['torch'] = None\n"
        "from darkread.cli import build_parser\n"
        "args = build_parser().parse_args(['train', 'fit', '--minutes', '1'])\n"
        "assert args.minutes == 1.0 and callable(args.func)\n"
        "print('ok')\n"
    )
    result = subprocess.run([sys.executable, "-c", script], check=False, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr


@pytest.mark.slow
def test_reproduce_synthesises_missing_sets_then_fits_and_writes_the_card(shard_writer, tmp_path: Path, monkeypatch) -> None:
    from darkread.models.train import pipeline

    made: list[str] = []

    def fake_generate(recipe, root, workers: int) -> None:
        Path(root).mkdir(parents=True)
        shard_writer(Path(root) / "shard-00000.npz", recipe.samples, seed=len(made))
        made.append((Path(root).name, recipe.samples, recipe.lux, recipe.more_fonts))

    monkeypatch.setattr(pipeline, "generate_dataset", fake_generate)
    config = FitConfig(batch_size=8, warmup_steps=1, max_epochs=1, threads=1, validation_samples=4,
                       net=NetConfig(widths=(4, 8, 8, 8), blocks=(1, 1, 1)).to_dict())
    models = tmp_path / "models"
    info = pipeline.reproduce(tmp_path / "train", tmp_path / "val", tmp_path / "run", config=config,
                              train_samples=24, val_samples=6, models_dir=models, figure=None)
    dim = (4.0, 40.0)
    assert made == [("train", 24, None, False), ("dim", 4, dim, False), ("dim_more_fonts", 4, dim, True), ("val", 6, None, False)]
    assert set(info["timings_s"]) >= {"synthesise train (24 windows)", "synthesise dim (4 windows)", "synthesise val (6 windows)",
                                      "fit", "evaluate"}
    assert (models / "MODEL_CARD.md").is_file() and (models / "binary_unet.onnx").is_file()


def test_the_network_shape_comes_from_the_options_else_the_init_network_else_the_default(tmp_path: Path) -> None:
    from darkread.cli import build_parser
    from darkread.lab.train.cli import _net_config
    from darkread.models.train.export import export_onnx
    from darkread.models.train.net import BinaryUNet

    parser = build_parser()
    assert _net_config(parser.parse_args(["train", "fit"])) == NetConfig()
    wide = _net_config(parser.parse_args(["train", "fit", "--widths", "8", "16", "32", "96", "--blocks", "1", "2", "8"]))
    assert wide.widths == (8, 16, 32, 96) and wide.blocks == (1, 2, 8) and wide.head == "shuffle"
    exported = export_onnx(BinaryUNet(wide).eval(), tmp_path / "wide.onnx")
    assert _net_config(parser.parse_args(["train", "fit", "--init", str(exported)])) == wide
    assert _net_config(parser.parse_args(["train", "fit", "--init", str(exported), "--head", "full"])).head == "full"
    with pytest.raises(SystemExit):
        parser.parse_args(["train", "fit", "--widths", "8", "16", "0", "64"])

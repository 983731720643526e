from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from darkread.edge.errors import ModelError
from darkread.edge.reconstruct import Reconstructor, default_model_path
from darkread.lab import BAND_NETWORK, FULL_NETWORK, PREVIOUS_NETWORK


@pytest.fixture(scope="module")
def random_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    torch = pytest.importorskip("torch")
    from darkread.models.train.export import export_onnx
    from darkread.models.train.net import BinaryUNet

    torch.manual_seed(0)
    return export_onnx(BinaryUNet(), tmp_path_factory.mktemp("model") / "net.onnx")


def _voxel(seed: int, batch: int | None = None) -> np.ndarray:
    rng = np.random.default_rng(seed)
    shape = (4, 100, 200) if batch is None else (batch, 4, 100, 200)
    return (rng.normal(size=shape) * (rng.random(shape) < 0.05)).astype(np.float32)


def test_single_window_gives_a_binary_uint8_mask(random_model: Path) -> None:
    rec = Reconstructor(random_model, warmup=1)
    mask = rec(_voxel(0))
    assert rec.input_shape == (4, 100, 200)
    assert mask.shape == (100, 200) and mask.dtype == np.uint8
    assert set(np.unique(mask)) <= {0, 1}


def test_batch_equals_windows_one_by_one(random_model: Path) -> None:
    rec = Reconstructor(random_model, warmup=0)
    batch = _voxel(1, batch=3)
    logits = rec.logits(batch)
    assert logits.shape == (3, 100, 200) and logits.dtype == np.float32
    for i in range(3):
        np.testing.assert_allclose(rec.logits(batch[i]), logits[i], rtol=1e-5, atol=1e-5)
    assert rec.logits(np.zeros((0, 4, 100, 200), np.float32)).shape == (0, 100, 200)


def test_wrong_input_shape_is_a_value_error(random_model: Path) -> None:
    with pytest.raises(ValueError, match=r"\[4,100,200\]"):
        Reconstructor(random_model, warmup=0).logits(np.zeros((4, 100, 100), np.float32))


def test_missing_model_is_a_model_error(tmp_path: Path) -> None:
    with pytest.raises(ModelError, match="not found"):
        Reconstructor(tmp_path / "absent.onnx")


def test_model_of_the_wrong_shape_is_a_model_error(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    path = tmp_path / "wrong.onnx"
    # any window size is fine (it becomes the fovea), but the ink image must cover that window
    torch.onnx.export(torch.nn.Conv2d(3, 1, 1, stride=2), (torch.zeros(1, 3, 64, 64),), str(path), opset_version=17, dynamo=False)
    with pytest.raises(ModelError, match="output shape"):
        Reconstructor(path)
    flat = tmp_path / "flat.onnx"
    torch.onnx.export(torch.nn.Linear(8, 8), (torch.zeros(1, 8),), str(flat), opset_version=17, dynamo=False)
    with pytest.raises(ModelError, match="input shape"):
        Reconstructor(flat)


def test_garbage_file_is_a_model_error(tmp_path: Path) -> None:
    path = tmp_path / "garbage.onnx"
    path.write_bytes(b"not an onnx model")
    with pytest.raises(ModelError, match="cannot load"):
        Reconstructor(path)


shipped = pytest.mark.skipif(not default_model_path().is_file(), reason="no shipped model in this checkout yet")


@shipped
def test_shipped_model_is_found_and_is_deterministic() -> None:
    rec = Reconstructor()
    assert rec.path == default_model_path()
    voxel = _voxel(2)
    first = rec(voxel)
    assert first.shape == (100, 200) and set(np.unique(first)) <= {0, 1}
    assert np.array_equal(rec(voxel), first)
    assert np.array_equal(rec.logits(voxel), rec.logits(voxel))


@shipped
def test_shipped_model_runs_without_torch() -> None:
    script = textwrap.dedent(
        """
        import sys
        sys.modules["torch"] = None  # any `import torch` now raises ImportError
        import numpy as np
        import darkread.edge.reconstruct as reconstruct
        mask = reconstruct.Reconstructor()(np.zeros((4, 100, 200), np.float32))
        assert mask.shape == (100, 200) and mask.dtype == np.uint8
        loaded = [name for name, mod in sys.modules.items() if name.split(".")[0] == "torch" and mod is not None]
        assert not loaded, loaded
        print("ok")
        """
    )
    result = subprocess.run([sys.executable, "-c", script], check=False, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "ok"


@shipped
def test_the_bound_input_window_infers_what_a_plain_grid_does() -> None:
    """``input_window``: the grid binned in place gives the same logits and mask as the grid passed
    in; batches (the free batch axis) agree with single windows (the batch axis fixed at 1)."""
    rec = Reconstructor(warmup=0)
    assert rec.input_window is not None and rec.input_window.shape == rec.input_shape
    for seed in range(3):
        voxel = _voxel(10 + seed)
        rec.input_window[...] = voxel
        assert np.array_equal(rec.logits(rec.input_window), rec.logits(voxel))
        assert np.array_equal(rec(rec.input_window), rec(voxel))
    batch = _voxel(20, batch=2)
    logits = rec.logits(batch)
    for i in range(2):
        np.testing.assert_allclose(rec.logits(batch[i]), logits[i], rtol=1e-5, atol=1e-5)


def test_probability_from_logits_is_a_sigmoid_softened_by_the_temperature() -> None:
    from darkread.edge.reconstruct import probability_from_logits

    logits = np.array([-1e4, -3.0, 0.0, 3.0, 1e4], np.float32)
    p = probability_from_logits(logits, temperature=1.5)
    assert p.dtype == np.float32 and np.all(np.isfinite(p))
    np.testing.assert_allclose(p, 1.0 / (1.0 + np.exp(-np.clip(logits / 1.5, -60, 60))), rtol=1e-6)
    assert p[2] == 0.5 and p[0] < 1e-20 and p[4] == 1.0
    # a higher temperature means less confidence on both sides, never another side of one half
    q = probability_from_logits(logits, temperature=3.0)
    assert q[3] < p[3] and q[1] > p[1] and q[3] > 0.5 > q[1]
    assert logits[2] == 0.0  # the logits are not touched


@shipped
def test_ink_probability_is_above_one_half_exactly_where_the_mask_is_ink() -> None:
    rec = Reconstructor(warmup=0)
    for seed in range(3):
        voxel = _voxel(30 + seed)
        rec.input_window[...] = voxel
        p = rec.ink_probability(rec.input_window)
        assert p.shape == (100, 200) and p.dtype == np.float32 and 0.0 <= p.min() and p.max() <= 1.0
        np.testing.assert_array_equal((p > 0.5).astype(np.uint8), rec(voxel))
    with pytest.raises(ValueError, match="temperature"):
        Reconstructor(warmup=0, temperature=0.0)


def test_a_network_carries_its_ink_temperature(random_model: Path, tmp_path: Path) -> None:
    """The ink probability's T comes from the model's metadata (1.5 without one), an argument overrides it."""
    import shutil

    from darkread.edge.reconstruct import INK_TEMPERATURE
    from darkread.models.train.calibrate import store_ink_temperature

    assert Reconstructor(random_model, warmup=0).temperature == INK_TEMPERATURE == 1.5
    tuned = store_ink_temperature(shutil.copy(random_model, tmp_path / "tuned.onnx"), 1.25)
    rec = Reconstructor(tuned, warmup=0)
    assert rec.temperature == 1.25
    voxel = _voxel(7)
    from darkread.edge.reconstruct import probability_from_logits

    rec.input_window[...] = voxel
    np.testing.assert_array_equal(rec.ink_probability(rec.input_window), probability_from_logits(rec.logits(voxel), 1.25))
    assert Reconstructor(tuned, warmup=0, temperature=2.0).temperature == 2.0
    store_ink_temperature(tuned, 0.75)  # stored again: replaced, not added
    assert Reconstructor(tuned, warmup=0).temperature == 0.75


def test_a_bad_stored_temperature_is_one_clear_error(random_model: Path, tmp_path: Path) -> None:
    import shutil

    import onnx

    from darkread.edge.reconstruct import INK_TEMPERATURE_KEY

    model = onnx.load(shutil.copy(random_model, tmp_path / "bad.onnx"))
    entry = model.metadata_props.add()
    entry.key, entry.value = INK_TEMPERATURE_KEY, "-1"
    onnx.save(model, str(tmp_path / "bad.onnx"))
    with pytest.raises(ModelError, match="ink_temperature.*calibrate --store"):
        Reconstructor(tmp_path / "bad.onnx", warmup=0)


@shipped
def test_the_shipped_networks_carry_the_temperatures_they_were_read_at() -> None:
    """The shipped network is read at T = 1.5 (stored), the one before it at 1.0 (stored), the first one
    (no metadata) at 1.5."""
    shipped_model = default_model_path()
    assert Reconstructor(shipped_model, warmup=0).temperature == 1.5
    assert Reconstructor(shipped_model.with_name("binary_unet_int8.onnx"), warmup=0).temperature == 1.5
    assert Reconstructor(PREVIOUS_NETWORK, warmup=0).temperature == 1.0
    assert Reconstructor(FULL_NETWORK, warmup=0).temperature == 1.5
    assert Reconstructor(BAND_NETWORK, warmup=0).temperature == 1.5  # the tune carries its base's temperature

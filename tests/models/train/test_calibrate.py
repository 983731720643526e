"""The ink temperature fit: temperature scaling by log-loss on held-out windows."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.models.train.calibrate import fit_temperature, log_loss, reliability


def test_the_fit_finds_the_temperature_the_targets_were_drawn_with() -> None:
    """Targets drawn as Bernoulli(sigmoid(z / 2)): the logits z are over-confident by 2."""
    rng = np.random.default_rng(0)
    logits = rng.normal(0.0, 4.0, size=(40, 50, 50)).astype(np.float32)
    targets = (rng.random(logits.shape) < 1.0 / (1.0 + np.exp(-logits / 2.0))).astype(np.uint8)
    result = fit_temperature(logits, targets)
    assert result.temperature == 2.0 and result.windows == 40
    assert min(result.losses.values()) == result.losses[2.0] < result.losses[1.0]
    for lower, share, pixels in result.reliability:  # calibrated at the fitted temperature
        if pixels > 5000:
            assert share == pytest.approx(lower + 0.05, abs=0.03)
    assert "| 2 (best) |" in result.to_markdown()


def test_log_loss_and_reliability_by_hand() -> None:
    assert log_loss(np.array([0.0]), np.array([1]), 1.0) == pytest.approx(np.log(2.0))
    table = reliability(np.array([0.05, 0.05, 0.95, 1.0]), np.array([0, 1, 1, 1]), bins=10)
    assert table[0] == (0.0, 0.5, 2) and table[9] == (0.9, 1.0, 2) and np.isnan(table[5][1])


def test_a_truncated_shard_is_one_line_naming_it(tmp_path) -> None:
    import subprocess
    import sys

    from darkread.models.train.data import load_shard

    bad = tmp_path / "shard-00000.npz"
    bad.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(ValueError, match="shard-00000.npz: not a readable training shard"):
        load_shard(bad)
    cli = [sys.executable, "-m", "darkread", "train", "calibrate"]
    result = subprocess.run([*cli, str(tmp_path)], capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 1 and "not a readable training shard" in result.stderr and "Traceback" not in result.stderr
    result = subprocess.run([*cli, str(tmp_path), "--limit", "0"], capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 2 and "must be at least 1" in result.stderr

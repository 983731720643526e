from __future__ import annotations

import json

import numpy as np

from darkread.models.train.data import iter_shards, load_dataset
from darkread.models.synth.fonts import HELD_OUT_FAMILIES, TRAIN_FAMILIES, faces_for
from darkread.models.synth.session import SessionSpec
from darkread.models.synth.shards import build_dataset, make_samples


def test_samples_are_deterministic_for_a_seed():
    spec = SessionSpec(duration_s=2.0, xheight_px=9.0, lux=50.0)
    a = make_samples(spec, 7, 2)
    b = make_samples(spec, 7, 2)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert a[2] == b[2]
    c = make_samples(spec, 8, 1)
    assert not np.array_equal(a[0][0], c[0][0])


def test_sample_shapes_and_target_convention():
    voxels, targets, metas = make_samples(SessionSpec(duration_s=2.0, xheight_px=12.0, lux=200.0), 3, 2)
    assert voxels.shape == (2, 4, 100, 200) and voxels.dtype == np.float16
    assert targets.shape == (2, 100, 200) and targets.dtype == np.uint8
    assert set(np.unique(targets)) <= {0, 1}
    assert targets.mean() < 0.5  # ink is the minority class (1 = ink)
    assert all(m.n_events >= 1600 for m in metas)
    assert np.count_nonzero(voxels[0]) > 500


def test_font_split_is_disjoint():
    assert not set(TRAIN_FAMILIES) & set(HELD_OUT_FAMILIES)
    assert {f.family for f in faces_for("held_out")} == set(HELD_OUT_FAMILIES)
    assert all(f.path.is_file() for f in faces_for("all"))


def test_shard_round_trip(tmp_path):
    manifest = build_dataset(tmp_path, 5, workers=1, seed=3, shard_size=3, progress=False)
    assert manifest["samples"] == 5 and len(manifest["shards"]) == 2
    on_disk = json.loads((tmp_path / "dataset.json").read_text())
    assert on_disk["fonts"]["held_out_families"] == list(HELD_OUT_FAMILIES)
    assert sum(on_disk["counts"]["motion"].values()) == 5 == sum(on_disk["counts"]["lux"].values())
    shards = list(iter_shards(tmp_path))
    assert [len(s) for s in shards] == [3, 2]
    with np.load(tmp_path / "shard-00000.npz") as z:
        assert z["targets"].shape == (3, 100, 25)
        assert list(z["target_shape"]) == [100, 200]
    data = load_dataset(tmp_path)
    assert data.voxels.shape == (5, 4, 100, 200) and data.targets.shape == (5, 100, 200)
    assert data.meta["motion"].dtype.kind == "U" and data.meta["font"][0] in {f.name for f in faces_for("train")}
    assert np.all(data.meta["lux"] > 0)


def test_a_lux_range_bounds_the_light_of_every_sample(tmp_path):
    manifest = build_dataset(tmp_path, 4, workers=1, seed=5, shard_size=4, progress=False, lux_range=(5.0, 12.0))
    assert manifest["parameters"]["lux"] == "log-uniform 5..12"
    lux = load_dataset(tmp_path).meta["lux"]
    assert np.all((lux >= 5.0) & (lux <= 12.0))


def test_a_reversed_lux_range_is_refused(tmp_path):
    import pytest

    with pytest.raises(ValueError, match="0 < LOW <= HIGH"):
        build_dataset(tmp_path, 4, workers=1, seed=5, progress=False, lux_range=(40.0, 4.0))

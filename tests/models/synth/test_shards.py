from __future__ import annotations

import json

import numpy as np
import pytest

from darkread.models.synth.fonts import HELD_OUT_FAMILIES, TRAIN_FAMILIES, faces_for
from darkread.models.synth.session import SessionSpec
from darkread.models.synth.shards import EVIDENCE_LAGS_MS, best_lag, build_dataset, ink_edges, make_samples
from darkread.models.train.data import iter_shards, load_dataset


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


def test_best_lag_finds_the_edges_the_events_show():
    mask = np.zeros((100, 200), np.uint8)
    mask[40:60, 50:58] = mask[40:60, 90:120] = 1
    maps = np.stack([ink_edges(np.roll(mask, k, axis=1)) for k in range(6)])  # the print moving right
    for k in range(6):
        assert best_lag(ink_edges(np.roll(mask, k, axis=1)), maps) == k
    assert best_lag(np.zeros((100, 200), np.float32), maps) == 0  # no events: no evidence of a lag
    assert best_lag(ink_edges(mask), np.stack([ink_edges(mask)] * 3)) == 0  # a still print: no lag


def test_evidence_targets_keep_the_windows_and_lag_in_the_dark():
    spec = SessionSpec(duration_s=2.0, xheight_px=10.0, lux=6.0, motion="walking")
    end = make_samples(spec, 5, 6)
    evidence = make_samples(spec, 5, 6, target_time="evidence")
    np.testing.assert_array_equal(end[0], evidence[0])  # same windows, same voxels
    lags = np.array([m.target_lag_us for m in evidence[2]])
    assert all(m.target_lag_us == 0 for m in end[2])
    assert lags.max() <= EVIDENCE_LAGS_MS[-1] * 1e3 and lags.mean() > 5_000  # events trail the page in the dark
    moved = [i for i, lag in enumerate(lags) if lag > 0]
    assert any(not np.array_equal(end[1][i], evidence[1][i]) for i in moved)
    with pytest.raises(ValueError, match="target time"):
        make_samples(spec, 5, 1, target_time="later")


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


def test_more_fonts_adds_the_computer_modern_families_to_training_sets_only(tmp_path):
    import pytest

    from darkread.models.synth.fonts import MORE_TRAIN_FAMILIES

    more = faces_for("train_more")
    assert more[: len(faces_for("train"))] == faces_for("train")  # the usual faces first: a set's draws stay put
    assert {f.family for f in more} == set(TRAIN_FAMILIES + MORE_TRAIN_FAMILIES)
    assert all(f.path.is_file() for f in more)
    assert not {f.family for f in faces_for("all")} & set(MORE_TRAIN_FAMILIES)  # validation sets unchanged
    manifest = build_dataset(tmp_path, 16, workers=1, seed=71, shard_size=16, progress=False, more_fonts=True)
    assert manifest["fonts"]["families_in_this_set"] == list(TRAIN_FAMILIES + MORE_TRAIN_FAMILIES)
    assert set(load_dataset(tmp_path).meta["font"]) <= {f.name for f in more}
    with pytest.raises(ValueError, match="--more-fonts is for training sets"):
        build_dataset(tmp_path / "val", 4, workers=1, split="val", progress=False, more_fonts=True)


def test_a_sets_font_split_is_named_once_for_sessions_and_manifests():
    import pytest

    from darkread.models.synth.fonts import SHIFTED_FAMILIES, families_of, font_split

    assert font_split("train") == "train" and font_split("train", more_fonts=True) == "train_more"
    assert font_split("val") == "all" and font_split("train", held_out=True) == "held_out"
    assert font_split("val", regime="shifted") == "shifted" and families_of("shifted") == SHIFTED_FAMILIES
    assert families_of("all") == TRAIN_FAMILIES + HELD_OUT_FAMILIES
    with pytest.raises(ValueError, match="unknown font split 'bold'"):
        families_of("bold")


def test_pages_are_made_under_each_named_bias_profile_by_their_seed(tmp_path):
    from darkread.models.synth.shards import page_biases, shard_seed

    seeds = [shard_seed(5, "train", False, 0, page) for page in range(40)]
    drawn = [page_biases(("factory", "dark"), s) for s in seeds]
    assert {"factory", "dark"} == set(drawn) and 10 < drawn.count("dark") < 30
    assert all(page_biases(("factory",), s) == "factory" for s in seeds)
    manifest = build_dataset(tmp_path, 2, workers=1, seed=5, shard_size=2, progress=False, lux_range=(5.0, 6.0),
                             regime="grounded", biases=("factory", "dark"), motion_regime="grounded")
    assert manifest["parameters"]["biases"] == ["factory", "dark"] and manifest["parameters"]["motion_regime"] == "grounded"
    assert load_dataset(tmp_path).voxels.shape[0] == 2


def test_biases_other_than_factory_need_the_grounded_sensor(tmp_path):
    with pytest.raises(ValueError, match="grounded regime only"):
        build_dataset(tmp_path, 2, workers=1, progress=False, biases=("dark",))
    with pytest.raises(ValueError, match="bias profile 'night'"):
        build_dataset(tmp_path, 2, workers=1, progress=False, regime="grounded", biases=("night",))
    with pytest.raises(ValueError, match="--motion-regime 'wild'"):
        build_dataset(tmp_path, 2, workers=1, progress=False, motion_regime="wild")

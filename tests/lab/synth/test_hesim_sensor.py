"""The second simulator (hesim-3d's H-ESIM on our scene): recordings it makes are real recordings.

Skips when hesim-3d or torch is not installed (`make venv` installs them: the `hesim` extra plus
``pip install --no-deps hesim-3d``).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from darkread.lab.synth.hesim_sensor import STEP_US, hesim_missing
from darkread.lab.synth.simulators import simulator_for

pytestmark = pytest.mark.skipif(hesim_missing() is not None, reason=str(hesim_missing()))

# a small page, a fraction of a second: a few hundred H-ESIM steps over ~30 k pixels
SPEC_KW = dict(motion="normal", kind="pangram", seconds=0.25, seed=11, xheight_px=7.0, n_lines=2, line_chars=12,
               simulator="hesim")


def _record(out: Path, **changes):
    from darkread.edge.io.raw import read_raw
    from darkread.models.synth.recording import RecordingSpec, write_recording

    spec = replace(RecordingSpec(lux=30.0, **SPEC_KW), **changes)
    meta = write_recording(out, spec, progress=False, simulator=simulator_for(spec.simulator))
    return meta, read_raw(out / "events.raw").events


def _region_rate(meta: dict, ev: np.ndarray) -> float:
    """Events per second inside the simulated region (the page's events, not the dark fill)."""
    x0, y0, w, h = meta["simulated_region_xywh"]
    inside = (ev["x"] >= x0) & (ev["x"] < x0 + w) & (ev["y"] >= y0) & (ev["y"] < y0 + h)
    return float(inside.sum()) / meta["duration_s"]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> dict[str, tuple[Path, dict, np.ndarray]]:
    root = tmp_path_factory.mktemp("hesim")
    out = {}
    for name, changes in {"30": {}, "5": {"lux": 5.0}, "still": {"motion": "still"}}.items():
        meta, ev = _record(root / name, **changes)
        out[name] = (root / name, meta, ev)
    return out


def test_a_hesim_recording_decodes_with_the_meta_and_truth_of_ours(recordings) -> None:
    folder, meta, ev = recordings["30"]
    assert ev.size == meta["event_count"] > 1000
    assert np.all(np.diff(ev["t"]) >= 0)  # EVT3 words decode in time order
    assert ev["x"].max() < 1280 and ev["y"].max() < 720
    assert set(np.unique(ev["p"])) == {0, 1}
    x0, y0, w, h = meta["simulated_region_xywh"]
    inside = (ev["x"] >= x0) & (ev["x"] < x0 + w) & (ev["y"] >= y0) & (ev["y"] < y0 + h)
    assert {0, 1} <= set(np.unique(ev["p"][inside]))
    # H-ESIM stamps each event at the end of its interval
    rel = ev["t"][inside] - ev["t"][inside].min()
    assert np.all(rel % int(STEP_US) == 0)
    stored = json.loads((folder / "meta.json").read_text())
    assert stored["simulator"] == "hesim" and stored["sensor"]["preset"] == "sony_imx636"
    assert 0.003 < stored["sensor"]["intensity_per_lux"] < 0.004
    for name in ("general_eye_gaze.csv", "calibration.json", "text.txt", "pose_truth.npz", "page_ink.npz"):
        assert (folder / name).is_file(), name


def test_the_same_spec_gives_the_same_scene_gaze_and_text_as_our_simulator(recordings, tmp_path) -> None:
    from darkread.models.synth.recording import RecordingSpec, write_recording

    folder, meta, _ = recordings["30"]
    ours = write_recording(tmp_path, RecordingSpec(lux=30.0, **{**SPEC_KW, "simulator": "darkread"}), progress=False)
    from darkread.edge.io.gaze_csv import read_gaze_csv

    for name in ("text.txt", "calibration.json"):
        assert (folder / name).read_bytes() == (tmp_path / name).read_bytes(), name
    with np.load(folder / "pose_truth.npz") as a, np.load(tmp_path / "pose_truth.npz") as b:
        np.testing.assert_array_equal(a["H_mm_to_camera"], b["H_mm_to_camera"])
    theirs, mine = read_gaze_csv(folder / "general_eye_gaze.csv"), read_gaze_csv(tmp_path / "general_eye_gaze.csv")
    for column in ("t_us", "yaw_rad", "pitch_rad", "depth_m"):  # the rows (only the session uid, drawn after the events, differs)
        np.testing.assert_array_equal(getattr(theirs, column), getattr(mine, column))
    assert ours["simulated_region_xywh"] == meta["simulated_region_xywh"] and ours["simulator"] == "darkread"


def test_hesim_event_rate_rises_with_light_and_with_motion(recordings) -> None:
    """In a log sensor the edges' events barely depend on light above the dark offset (contrast is a
    ratio); at 5 lux paper is only 3x the dark offset, so contrast shrinks and the rate falls a little;
    head motion sweeps edges over many more pixels."""
    rate = {name: _region_rate(meta, ev) for name, (_, meta, ev) in recordings.items()}
    assert rate["30"] > 1.05 * rate["5"], rate
    assert rate["30"] > 1.5 * rate["still"], rate


def test_a_hesim_recording_reads_end_to_end(recordings) -> None:
    from darkread_cli import darkread

    folder, _, _ = recordings["30"]
    result = darkread("read", str(folder), "--json", "--out", str(folder / "read"))
    assert result.returncode == 0, result.stderr
    doc = json.loads(result.stdout)
    assert doc["frames"] > 0 and "cer" in doc

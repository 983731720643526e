"""Every benchmark runs (``--smoke``: tiny inputs, one repetition) and writes the keys ``make bench`` promises.

The values of a smoke run mean nothing; the keys, their number and their finiteness are the contract
that bench.json readers (docs, issues, the README table) rely on.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from darkread.lab.bench import BENCH_MODULES
from darkread.lab.bench.__main__ import main

DECODE = {
    "decode_mev_per_s", "evt3_decode_mev_per_s", "decode_vs_evt3_ratio", "decode_numpy_backend_mev_per_s",
    "decode_stream_64k_mev_per_s", "decode_synthetic_mev_per_s", "decode_synthetic_evt3_mev_per_s",
    "decode_synthetic_vs_evt3_ratio",
}
FOVEA = {
    "fovea_crop_us_per_window", "fovea_crop_naive_us_per_window", "voxel_us_per_window",
    "voxel_reused_out_us_per_window", "voxel_add_at_us_per_window", "voxel_speedup_vs_add_at_x",
}
SYNTH = {"synth_samples_per_s", "synth_sim_s_per_wall_s"}
IMU = {"edge_imu_live_ms_per_s"}
EDGE = {
    "edge_realtime_factor", "edge_decode_realtime_factor", "edge_latency_p50_ms", "edge_latency_p99_ms",
    "edge_uplink_kbyte_per_s", "edge_inferences_per_s", "edge_view_latency_p99_ms", "edge_realtime_factor_every_window",
    "edge_realtime_factor_on_change", "edge_events_decoded_per_s", "edge_events_decoded_per_s_roi",
    "edge_realtime_factor_full_view", "edge_realtime_factor_imu_roi", "edge_imu_roi_speedup",
}
CLOUD = {"cloud_ingest_frames_per_s_1", "cloud_ingest_frames_per_s_10", "cloud_ingest_frames_per_s_50"}
CLOUD_POSTGRES = {
    "cloud_ingest_pg_frames_per_s_1", "cloud_ingest_pg_frames_per_s_10", "cloud_ingest_pg_frames_per_s_50",
    "cloud_pg_replays_frames_stored", "cloud_pg_replays_frames_lost", "cloud_pg_replays_frames_duplicated",
    "cloud_pg_replays_failovers",
}  # fmt: skip


def cloud_keys() -> set[str]:
    """PostgreSQL's figures come with SQLite's wherever a server can be started."""
    from darkread.lab.fixtures.pg_server import PostgresUnavailable, find_bin_dir

    try:
        find_bin_dir()
    except PostgresUnavailable:
        return CLOUD
    return CLOUD | CLOUD_POSTGRES
STITCH = {"stitch_ms_per_frame", "stitch_ink_f1", "stitch_ink_f1_tol1px", "stitch_ocr_cer"}


def inference_keys() -> set[str]:
    from darkread.edge.reconstruct import default_model_path
    from darkread.lab import BAND_NETWORK, PREVIOUS_NETWORK
    from darkread.lab.bench.inference import INT8_FILENAME

    keys = {"inference_ms_fp32", "inference_ms_reference"} | ({"inference_cost_ratio_band_vs_shipped"} if BAND_NETWORK.is_file() else set())
    keys |= {"inference_ms_int8"} if default_model_path().with_name(INT8_FILENAME).is_file() else set()
    return keys | ({"inference_ms_previous_model", "inference_cost_ratio_vs_previous"}
                   if PREVIOUS_NETWORK.is_file() else set())


def ocr_keys() -> set[str]:
    from darkread.cloud.ocr.rapid import RapidOcrBackend
    from darkread.cloud.ocr.tesseract import TesseractBackend

    ready = [name for name, engine in (("rapidocr", RapidOcrBackend), ("tesseract", TesseractBackend)) if engine().ready()]
    return {f"ocr_{name}_{what}_xh{xh}" for name in ready for what in ("ms_per_page", "cer") for xh in (10, 7)}


def run_smoke(name: str, tmp_path: Path) -> dict[str, float]:
    out = tmp_path / "bench.json"
    assert main(["--only", name, "--smoke", "--out", str(out)]) == 0
    figures = json.loads(out.read_text())
    assert all(isinstance(v, (int, float)) and math.isfinite(v) for v in figures.values()), figures
    return figures


@pytest.mark.parametrize(("name", "keys"), [("decode", DECODE), ("fovea", FOVEA), ("synth", SYNTH), ("imu", IMU)])
def test_benchmark_writes_its_keys(name: str, keys: set[str], tmp_path: Path) -> None:
    assert set(run_smoke(name, tmp_path)) == keys


def test_cloud_benchmark_writes_its_keys(tmp_path: Path) -> None:
    assert set(run_smoke("cloud", tmp_path)) == cloud_keys()


def test_inference_benchmark_writes_its_keys(tmp_path: Path) -> None:
    assert set(run_smoke("inference", tmp_path)) == inference_keys()


def test_edge_benchmark_writes_its_keys(tmp_path: Path) -> None:
    figures = run_smoke("edge", tmp_path)
    assert set(figures) == EDGE
    assert figures["edge_realtime_factor"] > 0 and figures["edge_latency_p99_ms"] >= figures["edge_latency_p50_ms"]
    from darkread.edge.config import default_infer_mode

    assert figures["edge_realtime_factor"] == figures["edge_realtime_factor_" + default_infer_mode().replace("-", "_")]
    # the sensor's ROI delivers fewer events than the whole sensor, even on the smoke run's small recording
    assert figures["edge_events_decoded_per_s_roi"] < figures["edge_events_decoded_per_s"]
    assert figures["edge_imu_roi_speedup"] == pytest.approx(figures["edge_realtime_factor_imu_roi"] / figures["edge_realtime_factor_full_view"])


@pytest.mark.slow  # rapidocr reads the stitched and the naive page
def test_stitch_benchmark_writes_its_keys(tmp_path: Path) -> None:
    figures = run_smoke("stitch", tmp_path)
    assert set(figures) == STITCH
    assert 0.0 <= figures["stitch_ink_f1"] <= 1.0


@pytest.mark.slow  # every installed OCR engine reads two pages
def test_ocr_benchmark_writes_its_keys(tmp_path: Path) -> None:
    assert set(run_smoke("ocr", tmp_path)) == ocr_keys()


def test_speech_benchmark_writes_its_keys(tmp_path: Path) -> None:
    figures = run_smoke("speech", tmp_path)
    assert set(figures) == {"speech_300_words_ms", "speech_300_words_peak_rss_mb"}
    assert figures["speech_300_words_ms"] > 0 and figures["speech_300_words_peak_rss_mb"] > 0


def test_gaze_benchmark_writes_its_keys(tmp_path: Path, shared_data: Path) -> None:
    from darkread.lab.gaze.scores import ARIA_RATES_HZ

    if not (shared_data / "reading_gaze" / "oz").is_dir():
        pytest.skip("../shared/data/reading_gaze/oz is not present")
    assert set(run_smoke("gaze", tmp_path)) == {f"gaze_fixation_onset_f1_{rate:g}hz" for rate in ARIA_RATES_HZ}


@pytest.mark.slow  # a real cloud per size and 20 wearers streaming the sample
def test_ask_benchmark_writes_its_keys(tmp_path: Path) -> None:
    figures = run_smoke("ask", tmp_path)
    assert set(figures) == {
        "read_demo_answer_ms", "read_demo_answer_ms_after_start_max", "read_demo_answer_ms_warm_max",
        "read_demo_answer_spread", "ask_p95_ms_300", "ask_p95_ratio_language", "cloud_cpu_ms_per_reading_s",
        "cloud_cpu_ms_per_reading_s_frames", "cloud_cpu_ms_per_reading_s_views", "cloud_cpu_ms_per_reading_s_asking_2hz",
        "wearers_ask_p95_ms_20", "wearers_frames_exactly_once_20",
        "wearers_burst_ask_p95_ms_20", "wearers_burst_frames_exactly_once_20",
    }
    assert figures["wearers_frames_exactly_once_20"] == figures["wearers_burst_frames_exactly_once_20"] == 1.0


def test_every_benchmark_module_is_tested() -> None:
    tested = {"decode", "fovea", "synth", "imu", "gaze", "cloud", "ask", "speech", "inference", "edge", "stitch", "ocr"}
    assert {name.rsplit(".", 1)[-1] for name in BENCH_MODULES} == tested


def test_an_unknown_benchmark_is_a_usage_error(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["--only", "nosuch", "--out", str(tmp_path / "bench.json")])
    assert exit_info.value.code == 2
    assert "invalid choice: 'nosuch'" in capsys.readouterr().err
    assert not (tmp_path / "bench.json").exists()

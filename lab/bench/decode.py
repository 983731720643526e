"""EVT 3.0 decode throughput: darkread's decoder next to the ``evt3`` package (Rust).

Each file is decoded from memory (header stripped) several times, alternating the two decoders so
both see the same machine load; the best run counts. The streaming reader is measured on the
sample recording with 64 KiB chunks, file reads included, next to the whole-buffer decode.
The numpy fallback (used when numba is missing) is measured too. Without ``../shared/data`` the
benchmark encodes a synthetic 1280x720 stream instead.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from darkread.edge.events import make_events
from darkread.edge.io.evt3 import decode_evt3, encode_evt3
from darkread.edge.io.raw import RawReader
from darkread.edge.io.raw_header import RawHeader, format_raw_header, parse_raw_header
from darkread.lab.bench import BenchContext, Figure

FILES = {
    "gen41_hd": "real_events/gen41_hd_evt3__expelliarmus_evt3_sample.raw",
    "hd_erc": "real_events/hd_evt3_trigger_erc__event_camera_codecs.raw",
    "vga_trigger": "real_events/vga_evt3_trigger__event_camera_py.raw",
    "sample": "sample_recording/events.raw",
}
STREAM_CHUNK_BYTES = 64 * 1024
GOAL = ">= 0.5x evt3"


def _best(fn: Callable[[], object], repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        started = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - started)
    return best


def _inputs(ctx: BenchContext) -> dict[str, Path]:
    if ctx.shared_data is not None and not ctx.smoke:
        found = {name: ctx.shared_data / rel for name, rel in FILES.items()}
        found = {name: path for name, path in found.items() if path.is_file()}
        if found:
            return found


    rng = np.random.default_rng(0)
    n = 20_000 if ctx.smoke else 500_000
    events = make_events(
        rng.integers(0, 1280, n),
        rng.integers(0, 720, n),
        rng.integers(0, 2, n),
        np.sort(rng.integers(5_000_000, 7_000_000, n)),
    )
    path = ctx.scratch / "synthetic.raw"
    path.write_bytes(format_raw_header(1280, 720) + encode_evt3(events))
    if not ctx.smoke:
        ctx.notes.append("decode: ../shared/data not found; measured on a synthetic encoded stream")
    return {"synthetic": path}


def _decode_figures(name: str, header: RawHeader, payload: bytes, repeat: int, evt3) -> tuple[list[Figure], dict]:
    events, _ = decode_evt3(payload, header.width, header.height)
    n = len(events)
    ours = evt3_time = float("inf")
    for _ in range(repeat):  # alternate so both decoders see the same load
        ours = min(ours, _best(lambda: decode_evt3(payload, header.width, header.height), 1))
        if evt3 is not None:
            evt3_time = min(evt3_time, _best(lambda: evt3.decode_bytes(payload, header.width, header.height), 1))
    numpy_time = _best(lambda: decode_evt3(payload, header.width, header.height, backend="numpy"), max(2, repeat // 3))
    rate = n / ours / 1e6
    figures = [Figure(f"decode_{name}_mev_per_s", rate, f"decode {name} ({n} ev), Mev/s")]
    result = {"events": n, "ours_s": ours, "evt3_s": evt3_time, "numpy_s": numpy_time}
    if evt3 is not None:
        ref = n / evt3_time / 1e6
        figures[0] = Figure(figures[0].key, rate, figures[0].label, f"evt3 {evt3.__version__}: {ref:.1f} Mev/s", GOAL)
        figures.append(Figure(f"decode_{name}_evt3_mev_per_s", ref, f"evt3 decode {name}, Mev/s"))
        figures.append(Figure(f"decode_{name}_vs_evt3_ratio", rate / ref, f"decode {name} vs evt3, x", "", GOAL))
    return figures, result


def _stream_figure(path: Path, whole_rate: float, repeat: int) -> Figure:
    def read_all() -> int:
        return sum(len(chunk) for chunk in RawReader(path, chunk_bytes=STREAM_CHUNK_BYTES))

    n = read_all()
    rate = n / _best(read_all, repeat) / 1e6
    return Figure(
        "decode_stream_64k_mev_per_s",
        rate,
        "RawReader 64 KiB chunks (file I/O incl.), Mev/s",
        f"whole-buffer decode: {whole_rate:.1f} Mev/s",
    )


def run(ctx: BenchContext) -> list[Figure]:
    try:
        import evt3
    except ImportError:
        evt3 = None
        ctx.notes.append("decode: evt3 package not installed; no reference decoder")
    repeat = ctx.runs(9, 3)
    figures: list[Figure] = []
    results: dict[str, dict] = {}
    for name, path in _inputs(ctx).items():
        data = path.read_bytes()
        header = parse_raw_header(data, str(path))
        more, results[name] = _decode_figures(name, header, data[header.data_offset :], repeat, evt3)
        figures.extend(more)
    events = sum(r["events"] for r in results.values())
    total_rate = events / sum(r["ours_s"] for r in results.values()) / 1e6
    summary = [Figure("decode_mev_per_s", total_rate, "EVT3 decode, all files, Mev/s")]
    if evt3 is not None:
        ref = events / sum(r["evt3_s"] for r in results.values()) / 1e6
        worst_name, worst = min(((k, r["evt3_s"] / r["ours_s"]) for k, r in results.items()), key=lambda kv: kv[1])
        summary[0] = Figure(
            "decode_mev_per_s", total_rate, summary[0].label, f"evt3 {evt3.__version__}: {ref:.1f} Mev/s", GOAL
        )
        summary.append(Figure("evt3_decode_mev_per_s", ref, "evt3 decode, all files, Mev/s"))
        summary.append(Figure("decode_vs_evt3_ratio", worst, f"decode vs evt3, worst file ({worst_name}), x", "", GOAL))
    numpy_rate = events / sum(r["numpy_s"] for r in results.values()) / 1e6
    summary.append(
        Figure(
            "decode_numpy_backend_mev_per_s",
            numpy_rate,
            "EVT3 decode, numpy fallback (no numba), Mev/s",
            f"compiled path: {total_rate:.1f} Mev/s",
        )
    )
    stream_name = "sample" if "sample" in results else next(iter(results))
    stream_path = _inputs(ctx)[stream_name]
    whole_rate = results[stream_name]["events"] / results[stream_name]["ours_s"] / 1e6
    summary.append(_stream_figure(stream_path, whole_rate, repeat))
    return summary + figures

"""What each way of getting the page off the glasses costs in bytes.

Per recording (one page): one RGB snapshot (raw, PNG, JPEG at several qualities), the whole event
stream as EVT3, the foveated event stream as EVT3, the stream the glasses sent (encoded wire
messages as counted by the uplink: one fused view per fixation in on-change mode,
zlib frames in every-window mode), and the stitched page as one encoded ``Page`` message (a CCITT
G4 stream, protocol version 3, as ``edge/pages.py`` sends it). Streams are also given per second. The ratios sit next to the paper's
figures: ~98 % of events removed by foveation, the frame stream ~20x below one RGB image, the
stitched page ~2400x below it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from darkread.core.image_codec import encode_jpeg, encode_png, read_image
from darkread.edge.config import PipelineConfig
from darkread.edge.fovea import FoveaConfig, foveate_along_gaze
from darkread.edge.gaze import GazeMapper
from darkread.edge.io.evt3_encode import encode_evt3
from darkread.edge.io.gaze_csv import read_gaze_csv
from darkread.edge.io.raw import read_raw
from darkread.edge.io.raw_header import read_raw_header
from darkread.edge.io.recording import open_recording
from darkread.proto.messages import Frame, Page, encode, pack_mask

JPEG_QUALITIES: tuple[int, ...] = (100, 80, 60, 40, 20)
PAPER_FOVEATION_REMOVED = 0.98
PAPER_FRAMES_VS_RGB = 20.0
PAPER_PAGE_VS_RGB = 2400.0


def image_sizes(image: np.ndarray, qualities: tuple[int, ...] = JPEG_QUALITIES) -> dict[str, int]:
    """Bytes of one image uncompressed, as PNG, and as JPEG at each quality (OpenCV encoders)."""
    array = np.ascontiguousarray(image)
    sizes = {"raw": int(array.nbytes), "png": len(encode_png(array))}
    for quality in qualities:
        sizes[f"jpeg{quality}"] = len(encode_jpeg(array, quality))
    return sizes


def raw_data_bytes(raw_path: str | Path) -> int:
    """Bytes of a RAW file's event data (the file without its text header)."""

    header = read_raw_header(raw_path)
    return Path(raw_path).stat().st_size - int(header.data_offset)


def frame_message_bytes(shape: tuple[int, int] | None = None) -> int:
    """Bytes of one encoded ``Frame`` wire message (a packed 1-bit mask: size does not depend on content).

    ``shape`` (rows, cols) defaults to the shipped model's window.
    """

    if shape is None:
        shape = (FoveaConfig().height, FoveaConfig().width)
    mask_shape, bits = pack_mask(np.zeros(shape, dtype=np.uint8))
    message = Frame(
        seq=2**31, frame_id=2**31, t_us=2**40, origin=(1080, 620), gaze_px=(640.5, 360.5), gaze_rad=(0.1, -0.1),
        events_used=1600, shape=mask_shape, bits=bits,
    )
    return len(encode(message))


PAGE_ENC = "g4"  # what edge/pages.py sends


def page_message_bytes(ink: np.ndarray, lines: list[tuple[int, int, int, int]] | None = None, enc: str = PAGE_ENC) -> int:
    """Bytes of one encoded ``Page`` wire message holding the binary page ``ink`` (1 = ink), as the
    glasses send it (``enc="g4"``: CCITT G4, v3; ``"png"``: a 1-bit PNG, v2; ``"bits"``: v1)."""

    shape, bits = pack_mask(np.asarray(ink, dtype=np.uint8))
    return len(encode(Page(seq=0, page_id=0, t_us=0, shape=shape, bits=bits, lines=tuple(lines or ()), enc=enc)))


def page_ink_from_png(path: str | Path) -> np.ndarray:
    """The cloud's stitched page (black text on white PNG) as an ink mask."""
    return (read_image(path) < 128).astype(np.uint8)


@dataclass
class Bandwidth:
    """Bytes for one recording (one page), with the recording's duration for per-second rates."""

    recording: str
    duration_s: float
    rgb: dict[str, int]  # one snapshot: raw, png, jpeg100 ... jpeg20
    events: int
    evt3_bytes: int
    events_foveated: int
    foveated_evt3_bytes: int
    frames: int
    frame_stream_bytes: int
    page_bytes: int
    frames_measured: bool = False  # frame figures come from a real edge run (else: estimated)
    rgb_wh: list[int] | None = None  # width, height of the RGB snapshot

    @property
    def foveation_removed(self) -> float:
        return 1.0 - self.events_foveated / self.events if self.events else 0.0

    def per_second(self, nbytes: int) -> float:
        return nbytes / self.duration_s if self.duration_s > 0 else math.nan

    def ratios(self) -> dict[str, float]:
        """The paper's three figures, measured here (RGB as PNG and as JPEG q80)."""
        frames_per_s = self.per_second(self.frame_stream_bytes)
        out = {"foveation_removed": self.foveation_removed}
        for fmt in ("raw", "png", "jpeg80"):
            if fmt in self.rgb:
                out[f"rgb_{fmt}_vs_frames_per_s"] = self.rgb[fmt] / frames_per_s if frames_per_s > 0 else math.nan
                out[f"rgb_{fmt}_vs_page"] = self.rgb[fmt] / self.page_bytes if self.page_bytes else math.nan
        return out

    def to_json(self) -> dict[str, Any]:
        doc = asdict(self)
        doc["ratios"] = self.ratios()
        return doc

    @staticmethod
    def from_json(doc: dict[str, Any]) -> Bandwidth:
        return Bandwidth(**{k: v for k, v in doc.items() if k != "ratios"})


def measure_bandwidth(
    recording_dir: str | Path,
    rgb_image: np.ndarray,
    *,
    frames: int | None = None,
    frame_stream_bytes: int | None = None,
    page_ink: np.ndarray | None = None,
) -> Bandwidth:
    """Bandwidth figures of one recording.

    ``frames`` / ``frame_stream_bytes`` are what a real edge run sent (``ReadResult.messages_sent``,
    ``bytes_sent``); without them the frame count is estimated as one frame per 1600 foveated
    events. ``page_ink`` is the stitched page; without it the page figure is 0.
    """

    recording = open_recording(recording_dir)
    raw = read_raw(recording.raw_path)
    events = raw.events
    sensor_wh = (int(raw.header.width), int(raw.header.height))
    mapper = GazeMapper(recording.calibration, read_gaze_csv(recording.gaze_path))
    foveated = foveate_along_gaze(events, mapper.pixels_at, sensor_wh)
    foveated_bytes = len(encode_evt3(foveated, width=sensor_wh[0])) if foveated.shape[0] else 0
    duration_s = float(recording.meta.get("duration_s") or 0.0)
    if duration_s <= 0 and events.shape[0] > 1:
        duration_s = (int(events["t"][-1]) - int(events["t"][0])) * 1e-6
    measured = frames is not None and frame_stream_bytes is not None
    if frames is None:
        frames = math.ceil(foveated.shape[0] / PipelineConfig().n_events)
    if frame_stream_bytes is None:
        frame_stream_bytes = frames * frame_message_bytes()
    return Bandwidth(
        recording=str(recording.path),
        duration_s=duration_s,
        rgb=image_sizes(rgb_image),
        events=int(events.shape[0]),
        evt3_bytes=raw_data_bytes(recording.raw_path),
        events_foveated=int(foveated.shape[0]),
        foveated_evt3_bytes=int(foveated_bytes),
        frames=int(frames),
        frame_stream_bytes=int(frame_stream_bytes),
        page_bytes=page_message_bytes(page_ink) if page_ink is not None else 0,
        frames_measured=measured,
        rgb_wh=[int(rgb_image.shape[1]), int(rgb_image.shape[0])],
    )

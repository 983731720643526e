"""Edge configuration: a TOML file, then ``DARKREAD_EDGE_<SECTION>_<KEY>`` environment overrides,
then command-line overrides (highest precedence).

Every setting lives in one small frozen dataclass per section, and the part that uses a section
takes that very type (``Pipeline`` a :class:`PipelineConfig`, ``Uplink`` an :class:`UplinkConfig`);
``edge/systemd/edge.toml`` is the documented example. The window size and the bin count are not
settings: they are the reconstruction model's input shape.
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from darkread.proto.messages import Mode

from darkread.core.redact import redact
from darkread.edge.roi import ROI_MODES, parse_roi_mode

ENV_PREFIX = "DARKREAD_EDGE_"


@dataclass(frozen=True)
class SourceConfig:
    kind: str = "replay"  # "replay" (a recording) or "evk4" (the USB camera)
    path: str = ""  # recording directory or .raw file (replay)
    gaze_csv: str = ""  # gaze CSV when ``path`` is a bare .raw file
    calibration: str = ""  # calibration.json when ``path`` is a bare .raw file (or for evk4)
    speed: float = 1.0  # replay pacing: 1 = wall clock, 2 = twice as fast, 0 = as fast as possible
    serial: str = ""  # evk4: device serial (empty: the first one)


@dataclass(frozen=True)
class GazeConfig:
    kind: str = "recording"  # "recording" (MPS CSV of the replay), "csv", "udp", "aria"
    path: str = ""  # csv: MPS general_eye_gaze.csv
    udp_host: str = "127.0.0.1"
    udp_port: int = 7007
    clock_offset_us: int | None = None  # gaze → event clock; None: from calibration.json
    max_age_ms: float = 100.0  # live feeds: older samples count as "no gaze"
    depth_prior_m: float = 0.45


@dataclass(frozen=True)
class ImuConfig:
    # where the head's rotation comes from (edge.imu_motion): "recording" (the replay's
    # closed_loop_trajectory.csv when it has one, else none), "csv" (path), "udp" (datagrams,
    # edge.sources.imu_feed), "aria" (Gen2 SDK) or "none" (the head's motion from the events only)
    kind: str = "recording"
    path: str = ""  # csv: an MPS closed_loop_trajectory.csv
    udp_host: str = "127.0.0.1"
    udp_port: int = 7008
    clock_offset_us: int | None = None  # device clock -> event clock; None: from calibration.json (the gaze's)


IMU_KINDS = ("recording", "csv", "udp", "aria", "none")
INFER_MODES = ("on-change", "every-window")  # ``[pipeline] infer``: the first is the default
FUSE_MODES = ("probability", "mask")  # ``[pipeline] fuse``: the first is the default


@dataclass(frozen=True)
class PipelineConfig:
    n_events: int = 1600  # foveated events per voxel grid (and new ones that trigger a frame)
    period_ms: float = 50.0  # also make a frame after this long if any new foveated events arrived
    model: str = ""  # ONNX path; empty: the shipped model (its input shape sets window and bins)
    threads: int = 1
    ring_capacity: int = 1 << 19  # 8 MB: 0.5 s at 1 Mev/s, far more than a window needs
    lossless: bool = False  # True: the reader waits for inference instead of skipping windows
    stall_s: float = 5.0  # no events for this long: the watchdog is no longer fed (systemd restarts us)
    # the sensor delivers only the view's window and a margin, moved with the gaze (edge.roi; EVK4: less
    # USB traffic, a replay decodes less): "auto" while the head's motion is known from elsewhere and
    # healthy (an IMU: edge.head_motion), "on" always, "off" never (true/false read as on/off)
    sensor_roi: str = ROI_MODES[0]
    # measure the head's motion from all the sensor's events (edge.scene_motion) and send it with
    # each frame and view: the stitcher predicts from it. Not while the ROI is on (only the window's events come then)
    scene_motion: bool = True
    # move each window's events back along the head's motion during its span (edge.deblur): in dim
    # light a window spans 20-50 ms and a moving head smears its strokes over 4-10 px
    deblur: bool = True
    # drop a dim-light window's isolated events, shot noise, before its voxel grid (edge.denoise):
    # in dim light many of them have no event on the pixels around them (docs/denoise.md)
    denoise: bool = True
    # when to infer: "on-change" (during fixations, when the view changed; frames fused into one
    # view per fixation) or "every-window" (every n_events new foveated events, frames sent as they are)
    infer: str = INFER_MODES[0]
    min_interval_ms: float = 10.0  # on-change: at most one inference per this much event time while frames change the view ...
    settled_interval_ms: float = 400.0  # ... and per this much once a frame agreed with it (the view is sent first: one more frame adds little)
    settled_score: float = 0.85  # agreed: the frame registered onto its view at least this well (its match score) ...
    # ... and the network was this sure of it (view_fusion.doubt at most this): doubtful frames (dim light,
    # small text) agree and are still noisy, so their views take every frame (what it gains: docs/views.md)
    settle_max_doubt: float = 1.1
    renew_fraction: float = 0.5  # on-change: infer again once this share of n_events is new (windows overlap by the rest:
    # in dim light the frames that do not agree are what the page is averaged from; 1.0 read 10 and 5 lux worse) ...
    move_px: float = 6.0  # ... or the window moved this far since the last inference (a view's window is placed once)
    min_events: int = 400  # on-change: a frame may have fewer than n_events (low light), not fewer than this
    first_wait_ms: float = 60.0  # on-change: the first frame of a fixation comes this long into it (landing settled)
    view_every_ms: float = 250.0  # on-change: a long fixation sends its view this often
    dither_px: int = 20  # on-change: a view's frames alternate this far above and below its window (0: all in it)
    # on-change: what a view averages, the network's calibrated ink "probability" per frame or the
    # binary "mask" (a view holds 1-3 frames: a mask's average has too few levels to keep faint strokes;
    # frames doubted all over, in dim light, go in as masks either way: view_fusion.MAX_DOUBT)
    fuse: str = "probability"

    def __post_init__(self) -> None:
        object.__setattr__(self, "sensor_roi", parse_roi_mode(self.sensor_roi))  # (a boolean reads as on/off)


@dataclass(frozen=True)
class UplinkConfig:
    url: str = "ws://127.0.0.1:8000/v1/stream"  # or several instances: a TOML list, or comma-separated
    api_key: str = ""
    device_id: str = ""  # empty: the host name
    session_id: str = ""  # empty: resume the spool's session if frames wait in it, else a new one
    mode: Mode = "frames"  # "frames" (binary frames) or "pages" (stitched on the glasses)
    # empty: on disk under the user's state directory ($XDG_STATE_HOME/darkread/spool, else
    # ~/.local/state/darkread/spool); ":memory:" in memory only (what is unsent at exit is lost)
    spool_dir: str = ""
    spool_max_mb: float = 256.0
    drain_timeout_s: float = 30.0
    backoff_initial_s: float = 0.2
    backoff_max_s: float = 10.0
    ack_timeout_s: float = 15.0  # messages in flight and no ack advancing for this long: reconnect
    max_in_flight: int = 512
    page_every_s: float = 5.0  # pages mode: send the page this often
    heartbeat_s: float = 5.0
    open_timeout_s: float = 5.0
    stable_connection_s: float = 2.0  # a connection that lasted this long resets the backoff


SENSOR_PROFILES = ("auto", "factory", "dark")  # ``[sensor] profile``: the first is the default


@dataclass(frozen=True)
class SensorConfig:
    """The event sensor's bias profile (edge/sources/evk4/bias_profiles.py) and when it switches (edge/light.py)."""

    # "auto": the dark profile in dim light, chosen from the light level; "factory" or "dark": that one, always
    profile: str = SENSOR_PROFILES[0]
    lux: float = 0.0  # > 0: the light at the page is this (a lux meter's reading) instead of estimated from the events
    dark_below_lux: float = 15.0  # auto: into the dark profile below this light level ...
    bright_above_lux: float = 25.0  # ... back to factory above this one ...
    min_dwell_s: float = 10.0  # ... at most once per this much event time (a switch changes the noise it is read from)
    estimate_s: float = 1.0  # one estimate per this much event time
    settle_s: float = 0.5  # events this soon after a bias write, or after the stream starts, are not counted (the pixels settle)
    stride: int = 4  # every stride-th event is counted (the background is a rate: a sample suffices)
    # auto: through a sensor ROI the light cannot be read (edge/bias_control.py), so when none was read for
    # probe_every_s of event time the whole sensor is delivered for probe_s (0: never)
    probe_every_s: float = 60.0
    probe_s: float = 0.3


@dataclass(frozen=True)
class MetricsConfig:
    host: str = "127.0.0.1"
    port: int = 0  # 0: no HTTP endpoint
    log_every_s: float = 10.0


@dataclass(frozen=True)
class EdgeConfig:
    source: SourceConfig = field(default_factory=SourceConfig)
    gaze: GazeConfig = field(default_factory=GazeConfig)
    imu: ImuConfig = field(default_factory=ImuConfig)
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    uplink: UplinkConfig = field(default_factory=UplinkConfig)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)


_SECTION_TYPES = {
    "source": SourceConfig,
    "gaze": GazeConfig,
    "imu": ImuConfig,
    "pipeline": PipelineConfig,
    "sensor": SensorConfig,
    "uplink": UplinkConfig,
    "metrics": MetricsConfig,
}


def _coerce(raw: Any, default: Any, where: str) -> Any:
    """Convert a TOML or environment value to the type of the field's default."""
    try:
        if isinstance(default, bool):
            if isinstance(raw, str):
                if raw.lower() not in {"1", "0", "true", "false", "yes", "no", "on", "off"}:
                    raise ValueError(raw)
                return raw.lower() in {"1", "true", "yes", "on"}
            return bool(raw)
        if isinstance(default, int) or (default is None and where.endswith("clock_offset_us")):
            if isinstance(raw, str) and raw.strip() == "":
                return None if default is None else default
            return int(raw)
        if isinstance(default, float):
            return float(raw)
        if isinstance(raw, list) and where == "[uplink] url":  # several cloud instances (failover)
            return ",".join(str(item) for item in raw)
        return str(raw)
    except ValueError:
        raise ValueError(f"config {where}: cannot use {raw!r} (expected {type(default).__name__})") from None


FROM_THE_MODEL = {"fovea_height", "fovea_width", "bins"}  # former [pipeline] keys


def _section(name: str, values: Mapping[str, Any], base: Any) -> Any:
    cls = _SECTION_TYPES[name]
    known = {f.name for f in dataclasses.fields(cls)}
    updates = {}
    for key, raw in values.items():
        if name == "pipeline" and key in FROM_THE_MODEL:
            raise ValueError(f"config: [pipeline] {key} is gone: the window size and bins are the model's input shape")
        if key not in known:
            raise ValueError(f"config: unknown key [{name}] {key} (known: {', '.join(sorted(known))})")
        if name == "pipeline" and key == "sensor_roi":
            updates[key] = parse_roi_mode(raw)  # a mode that was a boolean: true/false still read
        else:
            updates[key] = _coerce(raw, getattr(base, key), f"[{name}] {key}")
    return dataclasses.replace(base, **updates)


def apply(config: EdgeConfig, values: Mapping[str, Mapping[str, Any]]) -> EdgeConfig:
    """Overlay ``{section: {key: value}}`` on ``config`` (unknown keys are errors)."""
    sections = {}
    for name, section_values in values.items():
        if name not in _SECTION_TYPES:
            raise ValueError(f"config: unknown section [{name}] (known: {', '.join(_SECTION_TYPES)})")
        sections[name] = _section(name, section_values, getattr(config, name))
    return dataclasses.replace(config, **sections)


def env_overrides(environ: Mapping[str, str]) -> dict[str, dict[str, str]]:
    """``DARKREAD_EDGE_UPLINK_API_KEY=k`` → ``{"uplink": {"api_key": "k"}}``."""
    out: dict[str, dict[str, str]] = {}
    for name, value in environ.items():
        if not name.startswith(ENV_PREFIX):
            continue
        rest = name[len(ENV_PREFIX) :].lower()
        section, _, key = rest.partition("_")
        if section not in _SECTION_TYPES or not key:
            raise ValueError(f"environment {name}: expected {ENV_PREFIX}<SECTION>_<KEY> with a section in {list(_SECTION_TYPES)}")
        out.setdefault(section, {})[key] = value
    return out


def load_config(
    path: Path | str | None = None,
    environ: Mapping[str, str] | None = None,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
) -> EdgeConfig:
    config = EdgeConfig()
    if path is not None:
        try:
            with open(path, "rb") as fh:
                data = tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"{path}: not valid TOML: {exc}") from None
        config = apply(config, data)
    config = apply(config, env_overrides(os.environ if environ is None else environ))
    if overrides:
        config = apply(config, overrides)
    return validate(config)


def default_infer_mode() -> str:
    """The inference mode the daemon, ``darkread read``, the bench and the evaluation use unless told."""
    return PipelineConfig().infer


def other_infer_mode(mode: str) -> str:
    """The mode that is not ``mode`` (the evaluation and the bench put both side by side)."""
    return next(m for m in INFER_MODES if m != mode)


def validate(config: EdgeConfig) -> EdgeConfig:
    urls = [part.strip() for part in config.uplink.url.split(",") if part.strip()]
    if not urls:
        raise ValueError("config [uplink] url: no cloud URL given")
    for url in urls:
        if not url.startswith(("ws://", "wss://")):
            raise ValueError(f"config [uplink] url: {redact(url)!r} is not a ws:// or wss:// URL")
    if config.uplink.mode not in {"frames", "pages"}:
        raise ValueError(f"config [uplink] mode must be 'frames' or 'pages', not {config.uplink.mode!r}")
    if config.source.kind not in {"replay", "evk4"}:
        raise ValueError(f"config [source] kind must be 'replay' or 'evk4', not {config.source.kind!r}")
    if config.gaze.kind not in {"recording", "csv", "udp", "aria"}:
        raise ValueError(f"config [gaze] kind must be recording, csv, udp or aria, not {config.gaze.kind!r}")
    if config.imu.kind not in IMU_KINDS:
        raise ValueError(f"config [imu] kind must be {', '.join(IMU_KINDS)}, not {config.imu.kind!r}")
    if config.imu.kind == "csv" and not config.imu.path:
        raise ValueError("config [imu] kind 'csv' needs [imu] path (an MPS closed_loop_trajectory.csv)")
    if config.source.speed < 0:
        raise ValueError("config [source] speed must be >= 0 (0 = as fast as possible)")
    if config.pipeline.n_events <= 0 or config.pipeline.period_ms <= 0:
        raise ValueError("config [pipeline] n_events and period_ms must be positive")
    if config.pipeline.infer not in INFER_MODES:
        raise ValueError(f"config [pipeline] infer must be 'on-change' or 'every-window', not {config.pipeline.infer!r}")
    intervals = (config.pipeline.min_interval_ms, config.pipeline.settled_interval_ms, config.pipeline.view_every_ms)
    if min(intervals) <= 0 or config.pipeline.min_events <= 0:
        raise ValueError("config [pipeline] min_interval_ms, settled_interval_ms, view_every_ms and min_events must be positive")
    if config.pipeline.fuse not in FUSE_MODES:
        raise ValueError(f"config [pipeline] fuse must be 'probability' or 'mask', not {config.pipeline.fuse!r}")
    if not 0 < config.pipeline.renew_fraction <= 1:
        raise ValueError("config [pipeline] renew_fraction is a share of a window's events: above 0, at most 1, "
                         f"not {config.pipeline.renew_fraction:g}")
    sensor = config.sensor
    if sensor.profile not in SENSOR_PROFILES:
        raise ValueError(f"config [sensor] profile must be auto, factory or dark, not {sensor.profile!r}")
    if sensor.lux < 0 or not 0 < sensor.dark_below_lux < sensor.bright_above_lux:
        raise ValueError("config [sensor] lux must be >= 0 (0: estimated from the events) and 0 < dark_below_lux < "
                         f"bright_above_lux, not {sensor.dark_below_lux:g} and {sensor.bright_above_lux:g}")
    if sensor.estimate_s <= 0 or sensor.min_dwell_s < 0 or sensor.settle_s < 0 or sensor.stride < 1:
        raise ValueError("config [sensor] estimate_s must be positive, min_dwell_s and settle_s >= 0, stride >= 1")
    if sensor.probe_every_s < 0 or not sensor.estimate_s / 4 <= sensor.probe_s <= sensor.estimate_s:
        raise ValueError(f"config [sensor] probe_every_s must be >= 0 (0: never) and probe_s between a quarter of estimate_s "
                         f"and estimate_s ({sensor.estimate_s / 4:g}-{sensor.estimate_s:g} s), not {sensor.probe_s:g}")
    if config.pipeline.dither_px < 0 or config.pipeline.settle_max_doubt <= 0:
        raise ValueError("config [pipeline] dither_px must be >= 0 (0: a view's frames all in its window) and settle_max_doubt positive")
    return config

"""A reading session: what is printed, where the page is, how the head moves, where the eyes go.

Shared by training shards and recordings; everything is drawn from one random generator, so a
session is reproducible from its seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from darkread.edge.io.calibration import Calibration
from darkread.edge.sources.evk4.bias_profiles import FACTORY, profile_offsets
from darkread.models.synth.biases import apply_profile
from darkread.models.synth.camera import random_calibration
from darkread.models.synth.fonts import FontFace, face_by_name, faces_for, font_split
from darkread.models.synth.gaze import Scanpath, TrackerModel, reading_scanpath
from darkread.models.synth.human_scanpath import SHIPPED, HumanScanpath, replay_scanpath
from darkread.models.synth.marker_page import MarkerPage, MarkerPageSpec, lay_out, mm_to_px
from darkread.models.synth.motion import MOTION_LEVELS, random_motion
from darkread.models.synth.page import PrintedPage, reflectance, render_page
from darkread.models.synth.scene import Scene, base_pose, desk_surround
from darkread.models.synth.sensor import (
    DEFAULT_F_NUMBER,
    GroundedSensorParams,
    SensorParams,
    regime_sensor_params,
    with_standard_laws,
)
from darkread.models.synth.sensor_profile import profile_at, profile_sensor_params
from darkread.models.synth.text import TEXT_KINDS, make_lines

TEXTURE_OVERSAMPLING = 1.25  # texels per event pixel at the nominal pose


@dataclass(frozen=True)
class SessionSpec:
    """What may be fixed by the caller; ``None`` fields are drawn at random."""

    split: str = "train"  # "train" (training fonts and texts) or "val" (all fonts, validation texts)
    held_out: bool = False  # only the held-out font families
    lux: float | None = None
    motion: str | None = None
    kind: str | None = None
    font: str | None = None
    xheight_px: float | None = None
    n_lines: int | None = None
    line_chars: int | None = None
    duration_s: float = 10.0
    scanpath: str = "model"  # "model": the reading model; "human": a real reader's fixations replayed
    scanpath_file: str | None = None  # a human scanpath file (default: the shipped oz reader)
    regime: str = "standard"  # "shifted": a sensor and a font training never saw (sensor.REGIMES)
    markers: bool = False  # print the text as a marker page (marker_page.py) instead of a plain page
    more_fonts: bool = False  # split "train": draw from fonts.MORE_TRAIN_FAMILIES too
    f_number: float = DEFAULT_F_NUMBER  # the event camera's lens (the grounded regime's chip illuminance)
    bias_profile: str = FACTORY  # the IMX636 biases (edge/sources/evk4/bias_profiles.py; modelled in "grounded")
    sensor_profile: str | None = None  # a measured sensor profile the grounded sensor is drawn from (sensor_profile.py)
    k_hz_per_chip_lux: float | None = None  # grounded: the photoreceptor's K fixed here (None: drawn over its band)
    standard_laws: tuple[str, ...] = ()  # grounded: laws put back to the standard model's (sensor.STANDARD_LAWS)
    motion_regime: str = "standard"  # the head motion's draws (motion.MOTION_REGIMES): "standard" or a grounded band
    full_view: bool = False  # the paper's edge in view with a textured desk around it (scene.desk_surround)

    def __post_init__(self) -> None:
        # a spec read back from JSON (spec.json, suite.json) holds a list here: the same spec, so equal
        object.__setattr__(self, "standard_laws", tuple(self.standard_laws))


SCANPATHS = ("model", "human")


@dataclass
class Session:
    spec: SessionSpec
    seed: int
    page: PrintedPage
    scene: Scene
    scanpath: Scanpath
    tracker: TrackerModel
    sensor: SensorParams
    kind: str
    xheight_px: float  # nominal x-height (pixels) the page was made for
    deg_per_texel: float
    extras: dict = field(default_factory=dict)
    marker_page: MarkerPage | None = None  # the laid-out page when the text is printed with markers
    texels_per_mm: float = 0.0  # texture resolution of ``page`` (marker pages: page mm -> texel via mm_to_px)

    @property
    def calib(self) -> Calibration:
        return self.scene.calib

    def with_lux(self, lux: float, rng: np.random.Generator) -> tuple[Scene, SensorParams]:
        """The same scene under another light level, with freshly drawn sensor parameters."""
        return replace(self.scene, lux=float(lux)), session_sensor(self.spec, rng, lux)


def session_sensor(spec: SessionSpec, rng: np.random.Generator, lux: float) -> SensorParams:
    """The sensor of a session: its regime's draw, run with the spec's bias profile.

    With ``sensor_profile`` the grounded sensor is drawn around a measured profile instead of its band;
    ``k_hz_per_chip_lux`` fixes its photoreceptor's K after the draw (the same draws otherwise, so a
    suite made at the band's ends and centre holds the same scenes and sensors but for K); ``standard_laws``
    put single laws back to the standard model's, to attribute the two models' difference.
    Biases are modelled in the grounded regime only; another regime with a profile other than factory
    is a ValueError rather than a silent factory sensor.
    """
    profile_offsets(spec.bias_profile)  # an unknown profile is named before anything is drawn
    if spec.sensor_profile is not None:
        if spec.regime != "grounded":
            raise ValueError(f"a sensor profile is drawn from by the grounded regime only (--regime grounded), not {spec.regime!r}")
        params: SensorParams = profile_sensor_params(profile_at(spec.sensor_profile), rng, lux, spec.f_number)
    else:
        params = regime_sensor_params(spec.regime, rng, lux, spec.f_number)
    if isinstance(params, GroundedSensorParams):
        if spec.k_hz_per_chip_lux is not None:
            params = replace(params, k_hz_per_chip_lux=float(spec.k_hz_per_chip_lux))
        return with_standard_laws(apply_profile(params, spec.bias_profile), spec.standard_laws)
    if spec.k_hz_per_chip_lux is not None or spec.standard_laws:
        raise ValueError(f"a fixed K or a standard law is the grounded regime's (--regime grounded), not {spec.regime!r}'s")
    if spec.bias_profile != FACTORY:
        raise ValueError(f"bias profile {spec.bias_profile!r}: biases are modelled in the grounded regime only "
                         f"(--regime grounded), not in {spec.regime!r}")
    return params


LUX_RANGE: tuple[float, float] = (4.0, 1200.0)  # the light of a training sample, log-uniform (lux)


def random_lux(rng: np.random.Generator, lo: float = LUX_RANGE[0], hi: float = LUX_RANGE[1]) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _pick_face(spec: SessionSpec, rng: np.random.Generator) -> FontFace:
    if spec.font is not None:
        return face_by_name(spec.font)
    faces = faces_for(font_split(spec.split, spec.held_out, spec.more_fonts, spec.regime))
    return faces[int(rng.integers(len(faces)))]


def make_session(spec: SessionSpec, seed: int) -> Session:
    rng = np.random.default_rng(seed)
    text_split = "val" if spec.split == "val" else "train"
    kind = spec.kind or str(rng.choice(TEXT_KINDS, p=[0.15, 0.3, 0.15, 0.4]))
    motion_level = spec.motion or str(rng.choice(MOTION_LEVELS, p=[0.3, 0.5, 0.2]))
    face = _pick_face(spec, rng)
    xh_px = float(spec.xheight_px if spec.xheight_px is not None else rng.uniform(5.0, 16.0))
    n_lines = int(spec.n_lines or rng.integers(3, 11))
    line_chars = int(spec.line_chars or rng.integers(20, 51))
    lines = [" ".join(line.split()) for line in make_lines(kind, n_lines, line_chars, rng, split=text_split)]
    lines = [line for line in lines if line] or ["x"]

    calib = random_calibration(rng)
    distance = float(rng.uniform(0.3, 0.7))
    xh_m = xh_px * distance / calib.fx
    xh_tex = xh_px * TEXTURE_OVERSAMPLING
    page = render_page(lines, face, xh_tex, xh_m / xh_tex, line_spacing=float(rng.uniform(1.25, 1.7)))
    texel_m = page.texel_m * xh_tex / page.xheight_tex  # keep the physical x-height exact after font rounding
    page.texel_m = texel_m
    marker_page = None
    if spec.markers:
        marker_page = lay_out(MarkerPageSpec(lines=tuple(lines), font=face.name))
        distance = marker_page.xheight_mm * 1e-3 * calib.fx / xh_px  # the printed size is fixed: the reader's distance gives the x-height
        page = printed_marker_page(marker_page, xh_tex / marker_page.xheight_mm)
        texel_m = page.texel_m
    paper = float(rng.uniform(0.7, 0.92))
    contrast = float(rng.uniform(0.7, 0.95))
    blur = float(rng.uniform(0.0, 0.6)) * TEXTURE_OVERSAMPLING
    reflect = reflectance(page, paper=paper, contrast=contrast, blur_tex=blur)
    rot, centre = base_pose(rng, distance, max_tilt_deg=12.0 if spec.markers else 20.0)
    lux = float(spec.lux) if spec.lux is not None else random_lux(rng)
    surround = float(rng.uniform(0.05, 0.4))  # a desk or clothing around the paper
    desk = None
    if spec.full_view:  # the whole view is simulated: the paper's edge and a desk with structure (own generator)
        desk = desk_surround(np.random.default_rng([seed, 5]), surround)
    elif np.random.default_rng([seed, 3]).random() < 0.8 or spec.markers:
        surround = paper  # usually the sheet extends beyond the field of view (no page edge in view)
    scene = Scene(page, reflect, calib, rot, centre, random_motion(motion_level, rng, spec.motion_regime), lux, surround,
                  surround=desk)
    deg_per_texel = math.degrees(texel_m / distance)
    if spec.scanpath == "model" and spec.scanpath_file is None:
        scanpath = reading_scanpath(page, spec.duration_s + 1.0, deg_per_texel, rng, start_line=0)
    elif spec.scanpath in SCANPATHS:
        human = HumanScanpath.load(spec.scanpath_file or SHIPPED)
        scanpath = replay_scanpath(page, human, spec.duration_s + 1.0, deg_per_texel, rng)
    else:
        raise ValueError(f"scanpath {spec.scanpath!r}: use one of {', '.join(SCANPATHS)}")
    return Session(
        spec=spec,
        seed=int(seed),
        page=page,
        scene=scene,
        scanpath=scanpath,
        tracker=TrackerModel.random(rng),
        sensor=session_sensor(spec, rng, lux),
        kind=kind,
        xheight_px=xh_px,
        deg_per_texel=deg_per_texel,
        extras={"paper": paper, "contrast": contrast, "print_blur_tex": blur, "distance_m": distance},
        marker_page=marker_page,
        texels_per_mm=1e-3 / texel_m,
    )


def printed_marker_page(page: MarkerPage, texels_per_mm: float) -> PrintedPage:
    """The marker page as the simulator's texture, ``texels_per_mm`` texels per page millimetre."""
    s = float(texels_per_mm)
    x0, y0, x1, y1 = mm_to_px(np.asarray(page.text_box_mm).reshape(2, 2), s).ravel()
    return PrintedPage(
        lines=list(page.spec.lines),
        font=page.spec.font,
        coverage=page.ink_at(s),
        texel_m=1e-3 / s,
        xheight_tex=page.xheight_mm * s,
        line_y=mm_to_px(np.asarray(page.line_y_mm), s),
        char_x=[mm_to_px(np.asarray(xs), s) for xs in page.char_x_mm],
        text_box=(float(x0), float(y0), float(x1), float(y1)),
    )


def choose_dt_us(scene: Scene, *, max_px_per_step: float = 0.5, lo_us: float = 125.0, hi_us: float = 500.0) -> float:
    """Time step keeping image motion under ``max_px_per_step`` (at least 2 kHz)."""
    ppd = scene.calib.fx * math.tan(math.radians(1.0))
    speed_px_s = max(scene.motion.max_speed_deg_s() * ppd, 1e-6)
    return float(np.clip(max_px_per_step / speed_px_s * 1e6, lo_us, hi_us))

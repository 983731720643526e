"""The glasses' RGB camera, simulated: one snapshot of the very scene a synthetic recording shows.

The RGB baseline (``darkread.lab.eval.rgb_baseline``) reads it with the same OCR, to answer the paper's
question: why not just take a photo? The snapshot is simulated from
the very scene a synthetic recording was made of (``darkread.models.synth``: page, print, pose,
head motion), through a simple physical camera model:

* a 2880 x 2880 rectified pinhole image at ~26 px/deg (the Aria RGB camera's resolution at the
  image centre; its 110 deg fisheye field is not modelled, the page sits near the centre), placed
  at the event camera's optical centre;
* auto-exposure metered on the page's paper (a best case for the baseline): the exposure lengthens
  as light falls until the cap (one 30 fps frame), then analogue gain makes up the rest up to its
  limit; beyond that the image gets darker;
* motion blur: the scene is rendered at sub-frame times spread over the exposure (head and page
  motion of the session) and averaged, at most half a pixel of motion between sub-frames;
* optics: a Gaussian lens blur of ``lens_psf_sigma_px`` (1 px: edges in the reference recording's
  ``rgb.png`` measure sigma ~1.25 px including its motion);
* a Bayer colour filter (RGGB): each photosite counts the electrons of one colour (a third of the
  light a three-plane model would collect), with photon shot noise (Poisson) and read noise
  (Gaussian); bilinear demosaicing on the linear raw image, gain, sRGB gamma, 8 bits; no ISP
  denoising;
* JPEG at ``jpeg_quality`` (Aria stores its RGB frames as JPEG);
* the OCR sees a grey crop around the page (the channels averaged), a fair start for the engine.

Electrons per lux are set from photometry of a small phone-class pixel (about 100 e-/s per lux on
white paper per colour channel): at 100 lux the exposure is already at its cap, as in the sample
recording's RGB snapshot (32 ms at 100 lux).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from darkread.core.image_codec import decode_image, encode_jpeg
from darkread.edge.io.intrinsics import RECTIFIED, Intrinsics
from darkread.models.synth.recording import RecordingSpec, recording_seconds, session_spec
from darkread.models.synth.scene import Region
from darkread.models.synth.session import make_session

if TYPE_CHECKING:
    from darkread.models.synth.recording import RecordingSpec
    from darkread.models.synth.scene import Region, Scene
    from darkread.models.synth.session import Session

SPEC_NAME = "spec.json"  # the synthesis spec a suite writes next to each recording


@dataclass(frozen=True)
class RgbCameraModel:
    """The glasses' RGB camera as the baseline models it (defaults: Aria-like)."""

    width: int = 2880
    height: int = 2880
    px_per_deg: float = 26.0  # at the image centre
    electrons_per_lux_s: float = 100.0  # per pixel and colour channel, white (reflectance 1) page
    target_electrons: float = 1000.0  # auto-exposure aims the paper at this signal
    min_exposure_s: float = 50e-6
    max_exposure_s: float = 1 / 30  # one frame at 30 fps
    max_gain: float = 16.0
    read_noise_electrons: float = 2.5
    paper_level: float = 0.5  # linear output level (0..1) the auto-exposure puts the paper at
    max_subframe_step_px: float = 0.5
    max_subframes: int = 64
    lens_psf_sigma_px: float = 1.0  # 0: a perfect lens
    bayer: bool = True  # False: three full colour planes with independent noise (no mosaic)
    jpeg_quality: int | None = 90  # None: the raw 8-bit image, no compression

    @property
    def focal_px(self) -> float:
        return self.px_per_deg / math.tan(math.radians(1.0))

    @property
    def principal_point(self) -> tuple[float, float]:
        return (self.width - 1) / 2, (self.height - 1) / 2

    @property
    def intrinsics(self) -> Intrinsics:
        """The rectified pinhole this camera images through."""
        cx, cy = self.principal_point
        return Intrinsics(self.width, self.height, self.focal_px, self.focal_px, cx, cy, RECTIFIED)


@dataclass(frozen=True)
class Exposure:
    exposure_s: float
    gain: float
    paper_electrons: float  # mean signal of the paper during this exposure


def auto_exposure(lux: float, paper_reflectance: float, camera: RgbCameraModel = RgbCameraModel()) -> Exposure:
    """Longer exposure as light falls, up to the cap; then gain, up to its limit."""
    if lux <= 0 or paper_reflectance <= 0:
        raise ValueError(f"lux and paper reflectance must be positive, got {lux} and {paper_reflectance}")
    rate = camera.electrons_per_lux_s * lux * paper_reflectance  # e-/s on the paper
    exposure_s = float(np.clip(camera.target_electrons / rate, camera.min_exposure_s, camera.max_exposure_s))
    signal = rate * exposure_s
    gain = float(np.clip(camera.target_electrons / signal, 1.0, camera.max_gain))
    return Exposure(exposure_s=exposure_s, gain=gain, paper_electrons=signal)


def pixel_rays(camera: RgbCameraModel, x0: int, y0: int, width: int, height: int) -> np.ndarray:
    """Normalised rays (x/z, y/z) of a block of the rectified pinhole image, float64 [h*w, 2]."""
    pinhole = camera.intrinsics
    xs = (np.arange(x0, x0 + width, dtype=np.float64) - pinhole.cx) / pinhole.fx
    ys = (np.arange(y0, y0 + height, dtype=np.float64) - pinhole.cy) / pinhole.fy
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def rgb_region(camera: RgbCameraModel, x0: int, y0: int, width: int, height: int) -> Region:

    return Region(int(x0), int(y0), int(width), int(height), pixel_rays(camera, x0, y0, width, height))


def project_rgb(points_camera: np.ndarray, camera: RgbCameraModel) -> np.ndarray:
    """Camera-frame points [N, 3] -> RGB image pixels [N, 2] (NaN behind the camera)."""
    return camera.intrinsics.project(points_camera)


def _page_texels(scene: Scene, margin_xheights: float) -> np.ndarray:
    """Texel corners of the text block grown by a margin, plus its centre."""
    x0, y0, x1, y1 = scene.page.text_box
    m = margin_xheights * scene.page.xheight_tex
    return np.array([[x0 - m, y0 - m], [x1 + m, y0 - m], [x1 + m, y1 + m], [x0 - m, y1 + m], [(x0 + x1) / 2, (y0 + y1) / 2]])


def page_crop_box(
    scene: Scene, t_s: float, camera: RgbCameraModel = RgbCameraModel(), *, margin_xheights: float = 3.0
) -> tuple[int, int, int, int]:
    """(x0, y0, w, h) of the RGB image around the text block at ``t_s``, clipped to the image."""
    uv = project_rgb(scene.points_camera(_page_texels(scene, margin_xheights)[:4], t_s), camera)
    x0, y0 = np.floor(uv.min(axis=0)).astype(int)
    x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + 1
    x0, y0 = max(int(x0), 0), max(int(y0), 0)
    x1, y1 = min(int(x1), camera.width), min(int(y1), camera.height)
    if x1 <= x0 or y1 <= y0:
        raise ValueError("the page is outside the RGB image")
    return x0, y0, x1 - x0, y1 - y0


def motion_during(scene: Scene, t_mid_s: float, exposure_s: float, camera: RgbCameraModel = RgbCameraModel()) -> float:
    """Longest image path (px) of the page's corners and centre during the exposure: the blur length."""
    times = t_mid_s + exposure_s * np.linspace(-0.5, 0.5, 9)
    texels = _page_texels(scene, 0.0)
    tracks = np.stack([project_rgb(scene.points_camera(texels, float(t)), camera) for t in times])  # [T, 5, 2]
    return float(np.linalg.norm(np.diff(tracks, axis=0), axis=2).sum(axis=0).max())


def exposure_reflectance(
    scene: Scene, region: Region, t_mid_s: float, exposure_s: float, camera: RgbCameraModel = RgbCameraModel()
) -> tuple[np.ndarray, int]:
    """Mean reflectance each pixel saw during the exposure (motion blur), and the sub-frame count."""
    blur_px = motion_during(scene, t_mid_s, exposure_s, camera)
    n = int(np.clip(math.ceil(blur_px / camera.max_subframe_step_px) + 1, 1, camera.max_subframes))
    times = [t_mid_s] if n == 1 else list(t_mid_s + exposure_s * (np.arange(n) + 0.5 - n / 2) / n)
    acc = np.zeros((region.height, region.width), dtype=np.float32)
    for t in times:
        acc += scene.reflectance(region, float(t))
    return acc / len(times), n


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """Linear 0..1 -> sRGB 0..1 (IEC 61966-2-1)."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def expose(
    reflectance: np.ndarray,
    lux: float,
    exposure: Exposure,
    rng: np.random.Generator,
    camera: RgbCameraModel = RgbCameraModel(),
) -> np.ndarray:
    """Reflectance [h, w] -> the 8-bit sRGB image [h, w, 3] the camera delivers."""

    reflect: np.ndarray = np.asarray(reflectance, dtype=np.float32)
    if camera.lens_psf_sigma_px > 0:
        reflect = cv2.GaussianBlur(reflect, (0, 0), camera.lens_psf_sigma_px, borderType=cv2.BORDER_REFLECT)
    mean_e = camera.electrons_per_lux_s * lux * exposure.exposure_s * reflect.astype(np.float64)
    to_linear = np.float32(exposure.gain * camera.paper_level / camera.target_electrons)
    # a Bayer sensor counts one colour per photosite; otherwise three full planes
    mean = mean_e if camera.bayer else np.broadcast_to(mean_e[..., None], mean_e.shape + (3,))
    electrons = rng.poisson(mean).astype(np.float32)
    electrons += rng.normal(0.0, camera.read_noise_electrons, mean.shape).astype(np.float32)
    linear = electrons * to_linear
    if camera.bayer:  # demosaicing on the linear raw image, as an ISP does
        raw = np.round(np.clip(linear, 0.0, 1.0) * 65535.0).astype(np.uint16)
        linear = cv2.cvtColor(raw, cv2.COLOR_BayerRG2RGB).astype(np.float32) / np.float32(65535.0)
    image = np.round(srgb_encode(linear) * 255.0).astype(np.uint8)
    return jpeg_round_trip(image, camera.jpeg_quality) if camera.jpeg_quality is not None else image


def jpeg_round_trip(image: np.ndarray, quality: int) -> np.ndarray:
    """The image as a JPEG decoder sees it after encoding at ``quality`` (RGB in, RGB out)."""
    return decode_image(encode_jpeg(image, quality), colour=True)


def to_grey(image: np.ndarray) -> np.ndarray:
    return image if image.ndim == 2 else np.round(image.mean(axis=2)).astype(np.uint8)


@dataclass
class RgbSnapshot:
    """One simulated RGB snapshot: the page crop the OCR reads, and how it was taken."""

    crop: np.ndarray  # uint8 [h, w, 3] sRGB, the region around the page
    crop_xywh: tuple[int, int, int, int]
    lux: float
    t_s: float
    exposure_s: float
    gain: float
    paper_electrons: float
    blur_px: float
    subframes: int
    full: np.ndarray | None = field(default=None, repr=False)  # uint8 [H, W, 3], when asked for

    def describe(self) -> dict[str, Any]:
        return {
            "lux": self.lux, "exposure_ms": round(self.exposure_s * 1e3, 3), "gain": round(self.gain, 2),
            "paper_electrons": round(self.paper_electrons, 1), "blur_px": round(self.blur_px, 2),
            "subframes": self.subframes, "crop_xywh": list(self.crop_xywh),
        }


def take_snapshot(
    session: Session,
    t_s: float,
    rng: np.random.Generator,
    camera: RgbCameraModel = RgbCameraModel(),
    *,
    full_frame: bool = False,
) -> RgbSnapshot:
    """Simulate the snapshot at session time ``t_s`` (the middle of the exposure)."""
    scene = session.scene
    exposure = auto_exposure(scene.lux, float(session.extras.get("paper", 0.85)), camera)
    box = page_crop_box(scene, t_s, camera)
    region = rgb_region(camera, *box)
    reflect, n_sub = exposure_reflectance(scene, region, t_s, exposure.exposure_s, camera)
    blur = motion_during(scene, t_s, exposure.exposure_s, camera)
    full = None
    if full_frame:
        whole = rgb_region(camera, 0, 0, camera.width, camera.height)
        frame = scene.reflectance(whole, t_s)
        x0, y0, w, h = box
        frame[y0 : y0 + h, x0 : x0 + w] = reflect
        full = expose(frame, scene.lux, exposure, rng, camera)
        crop = full[y0 : y0 + h, x0 : x0 + w].copy()
    else:
        crop = expose(reflect, scene.lux, exposure, rng, camera)
    return RgbSnapshot(
        crop=crop, crop_xywh=box, lux=float(scene.lux), t_s=float(t_s), exposure_s=exposure.exposure_s,
        gain=exposure.gain, paper_electrons=exposure.paper_electrons, blur_px=blur, subframes=n_sub, full=full,
    )


# -- recordings ----------------------------------------------------------------------------------


def recording_spec(recording_dir: str | Path) -> RecordingSpec:
    """The synthesis spec of a suite recording (``spec.json``), needed to re-create its scene."""

    path = Path(recording_dir) / SPEC_NAME
    if not path.is_file():
        raise FileNotFoundError(
            f"{path} is missing: the RGB baseline re-creates the scene of recordings made by "
            "`darkread eval make-suite`, which writes it"
        )
    return RecordingSpec(**json.loads(path.read_text(encoding="utf-8")))


def session_for(spec: RecordingSpec) -> Session:
    """The session ``write_recording(spec)`` simulated (same spec, same seed -> same scene)."""

    return make_session(session_spec(spec), spec.seed)


def snapshot_for_recording(
    recording_dir: str | Path, camera: RgbCameraModel = RgbCameraModel(), *, full_frame: bool = False
) -> RgbSnapshot:
    """The RGB snapshot of a suite recording's scene, in the middle of the recording."""
    recording_dir = Path(recording_dir)
    spec = recording_spec(recording_dir)
    session = session_for(spec)
    text_path = recording_dir / "text.txt"
    if text_path.is_file() and text_path.read_text(encoding="utf-8") != session.page.text:
        raise ValueError(f"{recording_dir}: {SPEC_NAME} does not re-create this recording's page (text differs)")

    rng = np.random.default_rng([spec.seed, 7])
    return take_snapshot(session, recording_seconds(spec, session) / 2, rng, camera, full_frame=full_frame)

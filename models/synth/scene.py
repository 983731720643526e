"""A page in front of the head-mounted camera: pose over time, irradiance and ink mask of a region.

The page is a plane; a texture texel (u, v) sits at ``R(t) (s u - c_x, s v - c_y, 0) + centre(t)``
in the camera frame (s = metres per texel, c = text-block centre). Each pixel of a region has a
fixed undistorted ray, so the texel a pixel sees is a plane homography of its ray: the warp is exact
under lens distortion, and ``cv2.remap`` samples the anti-aliased texture bilinearly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from darkread.edge.io.calibration import Calibration
from darkread.models.synth.camera import region_rays, rotation_xyz
from darkread.models.synth.motion import Motion
from darkread.models.synth.page import PrintedPage


@dataclass
class Region:
    """A rectangle of sensor pixels with their rays (fixed while the camera intrinsics are fixed)."""

    x0: int
    y0: int
    width: int
    height: int
    rays: np.ndarray  # [h*w, 2] undistorted normalised coordinates

    @property
    def rays32(self) -> tuple[np.ndarray, np.ndarray]:
        """The rays as two float32 [h, w] images (x/z, y/z), computed once."""
        if getattr(self, "_rays32", None) is None:
            shape = (self.height, self.width)
            self._rays32 = (
                np.ascontiguousarray(self.rays[:, 0], dtype=np.float32).reshape(shape),
                np.ascontiguousarray(self.rays[:, 1], dtype=np.float32).reshape(shape),
            )
        return self._rays32

    @staticmethod
    def of(calib: Calibration, x0: int, y0: int, width: int, height: int) -> Region:
        return Region(int(x0), int(y0), int(width), int(height), region_rays(calib, x0, y0, width, height))


@dataclass(frozen=True)
class Surround:
    """A textured surface around the paper, in the page's plane (a desk: grain, blotches, other
    sheets), tiled: ``texture`` texel (i, j) covers page texels ``(i, j) * scale``."""

    texture: np.ndarray  # float32 [h, w] reflectance, periodic
    scale: float  # page texels per texel of ``texture``

    def around(self, page: np.ndarray, mx: np.ndarray, my: np.ndarray) -> np.ndarray:
        """``page`` (reflectance texture) sampled at texel maps (mx, my), the surround where the maps
        leave it, the paper's edge anti-aliased as the page's own bilinear border would be."""
        inside = cv2.remap(page, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        h, w = page.shape
        cover = (np.clip(np.minimum(mx + 1.0, w - mx), 0.0, 1.0) * np.clip(np.minimum(my + 1.0, h - my), 0.0, 1.0))
        scale = np.float32(1.0 / self.scale)
        desk = cv2.remap(self.texture, mx * scale, my * scale, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        return (inside + (1.0 - cover) * desk).astype(np.float32)


def desk_surround(rng: np.random.Generator, level: float, size: int = 256, scale: float = 4.0) -> Surround:
    """A desk around the paper at mean reflectance ``level``: wood grain, blotches at two scales and a
    few darker or lighter rectangles with sharp edges (other sheets, a phone), tileable."""
    freq = np.fft.fftfreq(size)
    radius2 = freq[:, None] ** 2 + freq[None, :] ** 2

    def smooth_noise(sigma: float) -> np.ndarray:  # periodic: filtered in the spectrum
        spectrum = np.fft.fft2(rng.standard_normal((size, size))) * np.exp(-2.0 * (np.pi * sigma) ** 2 * radius2)
        field = np.fft.ifft2(spectrum).real
        return (field - field.mean()) / max(float(field.std()), 1e-9)

    y = np.arange(size)[:, None] * np.ones((1, size))
    grain = np.sin(2.0 * np.pi * int(rng.integers(6, 14)) * y / size + 2.5 * smooth_noise(12.0))
    tone = 1.0 + 0.25 * smooth_noise(10.0) + 0.1 * smooth_noise(2.0) + 0.15 * grain
    for _ in range(int(rng.integers(2, 5))):
        x0, y0 = rng.integers(0, size, 2)
        w, h = rng.integers(size // 8, size // 3, 2)
        ys, xs = (np.arange(y0, y0 + h) % size)[:, None], (np.arange(x0, x0 + w) % size)[None, :]
        tone[ys, xs] *= float(rng.uniform(0.5, 1.8))
    return Surround(np.clip(level * tone, 0.02, 0.95).astype(np.float32), float(scale))


@dataclass
class Scene:
    page: PrintedPage
    reflect: np.ndarray  # float32 texture reflectance (paper tone, ink, print blur)
    calib: Calibration
    base_rotation: np.ndarray  # [3, 3] page orientation in the camera frame at rest
    base_centre: np.ndarray  # [3] text-block centre in the camera frame at rest (m)
    motion: Motion
    lux: float
    background: float = 0.15  # reflectance of what surrounds the paper
    surround: Surround | None = field(default=None)  # what surrounds it when not uniform (a desk)

    # -- pose ------------------------------------------------------------------------------------
    def pose(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(R [3,3], centre [3]): page rotation and text-centre position in the camera frame."""
        head, trans, page = self.motion.at(t_s)
        r_head = rotation_xyz(*head)
        rot = r_head @ self.base_rotation @ rotation_xyz(*page)
        centre = r_head @ (self.base_centre + trans)
        return rot, centre

    def texel_to_camera(self, t_s: float) -> np.ndarray:
        """3x3 homography: texel (u, v, 1) -> camera-frame point on the page (m), up to scale 1."""
        rot, centre = self.pose(t_s)
        s = self.page.texel_m
        c = self.page.text_center_tex * s
        h = np.empty((3, 3))
        h[:, 0] = rot[:, 0] * s
        h[:, 1] = rot[:, 1] * s
        h[:, 2] = centre - rot[:, 0] * c[0] - rot[:, 1] * c[1]
        return h

    def points_camera(self, tex_xy: np.ndarray, t_s: float) -> np.ndarray:
        """Camera-frame 3-D points (m) of texels ``tex_xy`` [N, 2]."""
        tex = np.asarray(tex_xy, dtype=np.float64).reshape(-1, 2)
        return np.c_[tex, np.ones(len(tex))] @ self.texel_to_camera(t_s).T

    def project(self, tex_xy: np.ndarray, t_s: float) -> np.ndarray:
        """Event-image pixels [N, 2] of texels (full distortion model)."""
        return self.calib.project(self.points_camera(tex_xy, t_s))

    def xheight_px(self, t_s: float) -> float:
        """Lower-case x-height in pixels at the text centre."""
        c = self.page.text_center_tex
        half = self.page.xheight_tex / 2
        uv = self.project(np.array([[c[0], c[1] - half], [c[0], c[1] + half]]), t_s)
        return float(np.linalg.norm(uv[1] - uv[0]))

    # -- images ----------------------------------------------------------------------------------
    def texel_maps(self, region: Region, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        inv = np.linalg.inv(self.texel_to_camera(t_s)).astype(np.float32)
        rx, ry = region.rays32
        inv_w = 1.0 / (inv[2, 0] * rx + inv[2, 1] * ry + inv[2, 2])
        u = (inv[0, 0] * rx + inv[0, 1] * ry + inv[0, 2]) * inv_w
        v = (inv[1, 0] * rx + inv[1, 1] * ry + inv[1, 2]) * inv_w
        return u, v

    def reflectance(self, region: Region, t_s: float) -> np.ndarray:
        mx, my = self.texel_maps(region, t_s)
        if self.surround is not None:
            return self.surround.around(self.reflect, mx, my)
        return cv2.remap(
            self.reflect, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=float(self.background)
        )

    def irradiance(self, region: Region, t_s: float) -> np.ndarray:
        """Light reaching each pixel, in lux at the page (``lux * reflectance``), float32 [h, w]."""
        return self.reflectance(region, t_s) * np.float32(self.lux)

    def ink_mask(self, region: Region, t_s: float) -> np.ndarray:
        """The ideal print seen by the region at ``t_s``: uint8 [h, w], 1 = ink, 0 = paper."""
        mx, my = self.texel_maps(region, t_s)
        cov = cv2.remap(self.page.coverage, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        return (cov >= 0.5).astype(np.uint8)


def base_pose(
    rng: np.random.Generator, distance_m: float, *, max_tilt_deg: float = 20.0
) -> tuple[np.ndarray, np.ndarray]:
    """A page orientation and text-centre position in front of the camera at ``distance_m``."""
    tilt = np.radians([rng.uniform(-max_tilt_deg, max_tilt_deg), rng.uniform(-0.6, 0.6) * max_tilt_deg, rng.normal(0, 3)])
    rot = rotation_xyz(*tilt)
    direction = np.array([math.tan(math.radians(rng.normal(0, 3))), math.tan(math.radians(rng.normal(0, 3))), 1.0])
    centre = direction / np.linalg.norm(direction) * distance_m
    return rot, centre

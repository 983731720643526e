"""The page found without its markers: global search in a noisy event image, then the edge alignment."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.edge.calibrate.event_image import count_image
from darkread.edge.events import EVENT_CD_DTYPE
from darkread.models.synth.camera import random_calibration
from darkread.models.synth.marker_page import MarkerPageSpec, lay_out
from darkread.models.train.annotate import SensorRays, page_box, project_page, reference_points, refine_pose, render_coverage
from darkread.models.train.page_search import (
    edge_map,
    find_page,
    homography_from_affine,
    hot_pixel_mask,
)

LINES = ("Areopagitica, John Milton 1644", "as good almost kill a man as k", "ill a good book; who kills a m")


@pytest.fixture(scope="module")
def scene():
    """A page (3 lines, monospace, markers) ~3.3 px/mm on the sensor, rotated 3 degrees, tilted a little."""
    calib = random_calibration(np.random.default_rng(5))
    page = lay_out(MarkerPageSpec(lines=LINES, font="DejaVu Sans Mono"))
    c, s = np.cos(np.radians(3.0)), np.sin(np.radians(3.0))
    H_cam = np.array([[1e-3 * c, -1e-3 * s, -0.045], [1e-3 * s, 1e-3 * c, -0.03], [2e-5, 0.0, 0.43]])
    return calib, page, H_cam / H_cam[2, 2], SensorRays(calib)


def dim_light_events(calib, page, H, rays, seed: int = 0) -> np.ndarray:
    """25 ms of events at 10 lux in the shifted regime: the page's edges fire (~25 k events), shot
    noise of ~5 Hz on every pixel (~115 k) and a few hundred hot pixels at ~600 Hz."""
    rng = np.random.default_rng(seed)
    w, h = calib.width, calib.height
    rate = np.full((h, w), 5.0 * 0.025)
    x0, y0, bw, bh = page_box(H, page, calib)
    edges = edge_map(render_coverage(page.ink_at(6.0), 6.0, H, rays.box(x0, y0, bw, bh), (bh, bw)))
    rate[y0 : y0 + bh, x0 : x0 + bw] += 25_000 * edges / edges.sum()
    hot = rng.choice(w * h, 400, replace=False)
    rate.reshape(-1)[hot] += 600 * 0.025
    counts = rng.poisson(rate).reshape(-1)
    pixel = np.repeat(np.arange(w * h), counts)
    events = np.zeros(len(pixel), EVENT_CD_DTYPE)
    events["x"], events["y"] = pixel % w, pixel // w
    events["p"] = rng.integers(0, 2, len(pixel))
    events["t"] = np.sort(rng.integers(0, 25_000, len(pixel)))
    return events


def corner_error_px(H_est, H_true, page, calib) -> float:
    ref = reference_points(page)
    return float(np.abs(project_page(H_est, calib, ref) - project_page(H_true, calib, ref)).max())


def test_page_is_found_in_noise_and_the_alignment_makes_it_exact(scene):
    calib, page, H, rays = scene
    events = dim_light_events(calib, page, H, rays)
    hot = hot_pixel_mask(events, calib.width, calib.height, floor=6.0)  # 25 ms: ~15 events per hot pixel
    assert hot.sum() >= 350  # most of the 400 hot pixels (a few are within the noise)
    assert hot.sum() <= 420  # and hardly any page pixel
    events = events[~hot[events["y"], events["x"]]]
    match = find_page(count_image(events, calib.width, calib.height), page)
    assert match is not None and match.score > 0.5 and match.margin > 0.1
    assert match.px_per_mm == pytest.approx(calib.fx * 1e-3 / 0.43, rel=0.06)
    assert match.angle_deg == pytest.approx(3.0, abs=1.3)
    seed = homography_from_affine(match.affine, page, calib)
    assert corner_error_px(seed, H, page, calib) < 10  # within the alignment's reach
    refined = refine_pose(seed, events, page, page.ink_at(8.0), 8.0, calib, rays)
    assert refined is not None and refined[1] > 0.5
    assert corner_error_px(refined[0], H, page, calib) < 1.0


def test_noise_alone_or_another_page_is_not_taken_for_the_page(scene):
    calib, page, H, rays = scene
    events = dim_light_events(calib, page, H, rays, seed=1)
    noise = events[events["x"] < 200]  # a strip of the sensor the page is not in
    assert find_page(count_image(noise, calib.width, calib.height), page) is None
    other = lay_out(MarkerPageSpec(lines=("another page",), dictionary="DICT_6X6_50"))
    assert find_page(count_image(events, calib.width, calib.height), other) is None


def test_affine_to_homography_puts_the_page_where_the_affine_does(scene):
    calib, page, _, _ = scene
    affine = np.array([[3.0, -0.2, 400.0], [0.2, 3.0, 250.0]])
    H = homography_from_affine(affine, page, calib)
    pts = reference_points(page)
    assert np.abs(project_page(H, calib, pts) - (pts @ affine[:, :2].T + affine[:, 2])).max() < 0.5

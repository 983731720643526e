from __future__ import annotations

import numpy as np

from darkread.edge.calibrate.event_image import (
    burst_events,
    count_image,
    detection_image,
    find_bursts,
)
from darkread.edge.events import empty_events, make_events


def _burst(rng, t0, n, polarity, box):
    x0, y0, x1, y1 = box
    t = t0 + rng.exponential(300.0, n)
    return make_events(rng.integers(x0, x1, n), rng.integers(y0, y1, n), np.full(n, polarity), t.astype(np.int64))


def _stream(rng, onsets, per_burst=20_000):
    noise_n = 40_000
    noise = make_events(rng.integers(0, 640, noise_n), rng.integers(0, 480, noise_n), rng.integers(0, 2, noise_n),
                        rng.integers(0, 2_000_000, noise_n))
    parts = [noise] + [_burst(rng, t, per_burst, p, (100, 100, 300, 200)) for t, p in onsets]
    ev = np.concatenate(parts).view(np.ndarray)
    out = empty_events(ev.size)
    for name in ("x", "y", "p", "t"):
        out[name] = ev[name]
    return out[np.argsort(out["t"], kind="stable")]


def test_count_image_counts_per_pixel_and_polarity():
    ev = make_events([1, 1, 2], [0, 0, 1], [1, 0, 1], [0, 1, 2])
    assert count_image(ev, 4, 3)[0, 1] == 2
    assert count_image(ev, 4, 3, polarity=1).sum() == 2


def test_bursts_are_found_with_their_onset_and_polarity():
    rng = np.random.default_rng(0)
    onsets = [(300_000.0, 0), (750_000.0, 1), (1_400_000.0, 0)]
    bursts = find_bursts(_stream(rng, onsets))
    assert len(bursts) == 3
    for b, (t, p) in zip(bursts, onsets):
        assert abs(b.onset_us - t) < 100  # exponential rise: 5 % of the excess arrives within ~15 us
        assert b.polarity == p


def test_no_bursts_in_noise_or_empty_streams():
    rng = np.random.default_rng(1)
    assert find_bursts(_stream(rng, [])) == []
    assert find_bursts(empty_events()) == []


def test_detection_image_is_dark_where_the_burst_fired():
    rng = np.random.default_rng(2)
    ev = _stream(rng, [(500_000.0, 0)], per_burst=100_000)  # a flash: every pixel of the area fires a few times
    burst = find_bursts(ev)[0]
    image = detection_image(burst_events(ev, burst), 640, 480)
    assert image.dtype == np.uint8 and image.shape == (480, 640)
    assert image[120:180, 120:280].mean() < 60  # fired area: dark
    assert image[300:400, 400:600].mean() > 240  # noise removed: white

"""PNG and JPEG through the one codec module: lossless PNG, RGB order kept, one exception."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from darkread.core.errors import DarkreadError
from darkread.core.image_codec import ImageCodecError, decode_image, encode_jpeg, encode_png, read_image, write_png

images = st.one_of(
    hnp.arrays(np.uint8, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=24)),
    hnp.arrays(np.uint8, st.tuples(st.integers(1, 24), st.integers(1, 24), st.just(3))),
)


@settings(max_examples=60, deadline=None)
@given(images)
def test_png_round_trips_grey_and_rgb(image: np.ndarray) -> None:
    np.testing.assert_array_equal(decode_image(encode_png(image), colour=image.ndim == 3), image)


def test_rgb_stays_rgb_through_files(tmp_path: Path) -> None:
    red = np.zeros((4, 5, 3), np.uint8)
    red[..., 0] = 200
    path = write_png(tmp_path / "red.png", red)
    np.testing.assert_array_equal(read_image(path, colour=True), red)
    assert read_image(path).shape == (4, 5)


def test_jpeg_is_lossy_and_smaller_at_lower_quality() -> None:
    image = np.clip(np.random.default_rng(0).normal(128, 30, (64, 64, 3)), 0, 255).astype(np.uint8)
    assert len(encode_jpeg(image, 20)) < len(encode_jpeg(image, 90))
    decoded = decode_image(encode_jpeg(image, 20), colour=True)
    assert decoded.shape == image.shape and not np.array_equal(decoded, image)


@pytest.mark.parametrize("bad", [np.zeros((4, 4), np.float32), np.zeros((4, 4, 2), np.uint8), np.zeros((0, 3), np.uint8)])
def test_what_cannot_be_encoded_raises_the_one_error(bad: np.ndarray) -> None:
    with pytest.raises(ImageCodecError):
        encode_png(bad)


def test_what_cannot_be_decoded_raises_the_one_error(tmp_path: Path) -> None:
    assert issubclass(ImageCodecError, DarkreadError)
    with pytest.raises(ImageCodecError, match="not a readable image"):
        decode_image(b"not a png")
    with pytest.raises(ImageCodecError, match="missing.png"):
        read_image(tmp_path / "missing.png")

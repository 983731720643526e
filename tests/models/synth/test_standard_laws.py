"""A grounded sensor with one law put back to the standard model's: only that law changes."""

from __future__ import annotations

import json
from dataclasses import asdict

import numpy as np
import pytest

from darkread.models.synth.recording import RecordingSpec
from darkread.models.synth.sensor import (
    STANDARD_CENTRAL,
    GroundedSensorParams,
    MixedLawSensorParams,
    background_rate_curve,
    with_standard_laws,
)
from darkread.models.synth.session import SessionSpec

PAGE = np.array([0.05 * 5.0, 0.85 * 5.0], np.float32)  # ink and paper at 5 lux


def test_no_law_put_back_is_the_grounded_sensor_itself() -> None:
    grounded = GroundedSensorParams(lux=5.0)
    assert with_standard_laws(grounded, ()) is grounded


def test_the_standard_photoreceptor_changes_the_cutoff_alone() -> None:
    grounded = GroundedSensorParams(lux=5.0)
    mixed = with_standard_laws(grounded, ("photoreceptor",))
    assert isinstance(mixed, MixedLawSensorParams)
    expected = STANDARD_CENTRAL.cutoff_hz * PAGE / (PAGE + STANDARD_CENTRAL.cutoff_half_lux)
    np.testing.assert_allclose(mixed.cutoff_of(PAGE), expected, rtol=1e-6)
    np.testing.assert_allclose(mixed.log_intensity(PAGE), grounded.log_intensity(PAGE))
    sd_g, band_g = grounded.noise_sd_and_cutoff(PAGE)
    sd_m, band_m = mixed.noise_sd_and_cutoff(PAGE)
    np.testing.assert_allclose(sd_m, sd_g) and np.testing.assert_allclose(band_m, band_g)
    assert mixed.noise_process and mixed.shot_rate_hz() == 0.0


def test_the_standard_dark_current_raises_the_floor_through_the_lens() -> None:
    grounded = GroundedSensorParams(lux=5.0)
    mixed = with_standard_laws(grounded, ("dark-current",))
    floor = mixed.total_chip_lux(np.zeros(1, np.float32))[0]
    lens = grounded.total_chip_lux(np.ones(1, np.float32))[0] - grounded.dark_chip_lux
    assert floor == pytest.approx(STANDARD_CENTRAL.dark_lux * lens, rel=1e-5)
    assert floor > 10 * grounded.dark_chip_lux  # the standard floor is far above the fitted dark current
    np.testing.assert_array_less(grounded.cutoff_of(PAGE), mixed.cutoff_of(PAGE))  # more light: a faster pixel


def test_the_standard_noise_is_a_rate_again() -> None:
    mixed = with_standard_laws(GroundedSensorParams(lux=5.0, leak_rate_hz=0.03), ("noise",))
    assert not mixed.noise_process
    assert mixed.shot_rate_hz() == pytest.approx(STANDARD_CENTRAL.shot_rate_100lux_hz * 20.0)
    assert mixed.background_rate_hz() == pytest.approx(mixed.shot_rate_hz() + 0.03)
    rate = background_rate_curve(mixed, np.array([0.85 * 5.0]), pixels=256, seconds=2.0)[0]
    assert rate == pytest.approx(mixed.background_rate_hz(), rel=0.35)  # the simulated paper fires near the rate
    assert mixed.to_dict()["standard_laws"] == ["noise"] and "shot_rate_100lux_hz" in mixed.to_dict()


def test_a_spec_read_back_from_json_names_the_same_laws() -> None:
    """JSON writes the laws' tuple as a list; a spec read back (spec.json, suite.json) is still equal."""
    spec = RecordingSpec(lux=5.0, regime="grounded", k_hz_per_chip_lux=130.0, standard_laws=("noise", "photoreceptor"))
    again = RecordingSpec(**json.loads(json.dumps(asdict(spec))))
    assert again == spec and again.standard_laws == ("noise", "photoreceptor")
    assert SessionSpec(standard_laws=["noise"]).standard_laws == ("noise",)  # type: ignore[arg-type]

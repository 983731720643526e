"""The shipped light table is what the grounded sensor model gives (``darkread synth background-table``)."""

from __future__ import annotations

import numpy as np
import pytest

from darkread.edge.light import load_rate_curves
from darkread.lab.synth.background_table import background_table


def test_the_shipped_table_matches_the_model() -> None:
    """Re-made at two levels with fewer pixels: within 15 % of the shipped rates (Poisson spread ~5 %);
    a re-fitted noise model must re-make the table."""
    fresh = background_table(pixels=512, seconds=4.0, lux=(4.9, 11.533))
    shipped = load_rate_curves()
    for name, doc in fresh["profiles"].items():
        curve = shipped[name]
        expected = np.interp(doc["lux"], curve.lux, curve.rate_hz)
        np.testing.assert_allclose(doc["rate_hz"], expected, rtol=0.15)
        assert doc["dark_hz"] == pytest.approx(curve.dark_hz, rel=0.15)

"""IMX636 bias offsets (from factory) -> the grounded sensor model's parameters.

The IMX636's bias DACs are close to exponential in their code (each sets a subthreshold current),
so every mapping scales a parameter by ``exp(offset / codes_per_e_fold)``. The e-folds are chosen
from what is published (docs/sensor_model.md, "Biases"), and are the part of the model least
measured: NIST saw the lowest diff_on/off roughly halve the dim-light latency and the highest make it
3x (ON) to 10x (OFF) longer; OpenEB's recommended ranges bound each offset.

- ``diff_on`` / ``diff_off``: the ON / OFF contrast thresholds (``c_on``, ``c_off``);
- ``fo``: the source follower's low-pass, the ceiling of the photoreceptor's cut-off (``f_max_hz``);
  it cannot raise the cut-off above what the photocurrent allows (``K E``);
- ``hpf``: a high-pass on the change detector (0 = off, factory): the reference follows the signal
  with that cut-off, so slow changes fire nothing (``highpass_hz``);
- ``refr``: the refractory period, shorter for a higher code (``refractory_us``).
"""

from __future__ import annotations

import math
from dataclasses import replace

from darkread.edge.sources.evk4.bias_profiles import check_bias_offsets, profile_offsets
from darkread.models.synth.sensor import GroundedSensorParams

THRESHOLD_CODES_PER_E_FOLD = 110.0  # recommended diff_on -85..140: thresholds x0.46..x3.6
FO_CODES_PER_E_FOLD = 25.0  # recommended fo -35..55: the ceiling x0.25..x9
REFR_CODES_PER_E_FOLD = 60.0  # recommended refr -20..235: the refractory period x1.4..x0.02
HPF_FIRST_HZ = 0.1  # the high-pass's cut-off at hpf = 1 ...
HPF_CODES_PER_E_FOLD = 30.0  # ... rising to ~5 Hz at the recommended maximum 120


def highpass_hz(hpf_offset: int) -> float:
    """The change detector's high-pass cut-off for an hpf offset (factory 0: none)."""
    return 0.0 if hpf_offset <= 0 else HPF_FIRST_HZ * math.exp((hpf_offset - 1) / HPF_CODES_PER_E_FOLD)


def apply_biases(params: GroundedSensorParams, offsets: dict[str, int]) -> GroundedSensorParams:
    """``params`` (drawn at factory biases) as the sensor runs with bias ``offsets`` from factory.

    Unknown biases or offsets the driver would refuse are a ValueError (the driver's own check).
    """
    check_bias_offsets(offsets)
    full = {name: int(offsets.get(name, 0)) for name in ("diff_on", "diff_off", "fo", "hpf", "refr")}
    return replace(
        params,
        c_on=params.c_on * math.exp(full["diff_on"] / THRESHOLD_CODES_PER_E_FOLD),
        c_off=params.c_off * math.exp(full["diff_off"] / THRESHOLD_CODES_PER_E_FOLD),
        f_max_hz=params.f_max_hz * math.exp(full["fo"] / FO_CODES_PER_E_FOLD),
        refractory_us=params.refractory_us * math.exp(-full["refr"] / REFR_CODES_PER_E_FOLD),
        highpass_hz=highpass_hz(full["hpf"]),
        biases=tuple(sorted(full.items())),
    )


def apply_profile(params: GroundedSensorParams, profile: str) -> GroundedSensorParams:
    """``params`` under a named bias profile (edge/sources/evk4/bias_profiles.py)."""
    return apply_biases(params, profile_offsets(profile))

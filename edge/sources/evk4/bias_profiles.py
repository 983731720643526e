"""Named IMX636 bias profiles: offsets from factory the glasses switch between, and the simulator models.

Defined once here, so what the EVK4 driver writes (``Evk4Camera.set_biases(**BIAS_PROFILES[name])``)
and what a synthetic recording states it was made with (``darkread.models.synth.biases``) are the
same numbers.

``dark`` follows the direction of Prophesee's own low-light preset for the GenX320 (in openmv:
fo 34 -> 19, hpf 40 -> 0, diff_off 28 -> 19, diff_on 25 -> 24): lower contrast thresholds for
latency and sensitivity, paid in noise, which a stronger low-pass (lower fo) takes back in part;
no high-pass (the IMX636's factory hpf is already off). The offsets stay inside OpenEB's recommended
ranges (``registers.BIASES``).
"""

from __future__ import annotations

from darkread.edge.sources.evk4 import registers as regs

FACTORY = "factory"
DARK = "dark"

BIAS_PROFILES: dict[str, dict[str, int]] = {
    FACTORY: {},
    DARK: {"diff_on": -30, "diff_off": -30, "fo": -15, "hpf": 0, "refr": 0},
}


def check_bias_offsets(offsets: dict[str, int]) -> None:
    """ValueError naming the allowed range for any unknown bias or out-of-range offset."""
    for name, offset in offsets.items():
        spec = regs.BIASES.get(name)
        if spec is None:
            hint = " (diff is the reference of diff_on/diff_off and is not settable)" if name == "diff" else ""
            raise ValueError(f"unknown bias {name!r}{hint}; settable biases: {', '.join(regs.BIASES)}")
        if isinstance(offset, bool) or not isinstance(offset, int):
            raise ValueError(f"bias {name} offset must be an integer, got {offset!r}")
        lo, hi = spec.allowed
        if not lo <= offset <= hi:
            rlo, rhi = spec.recommended
            raise ValueError(
                f"bias {name} offset {offset} is outside the allowed range [{lo}, {hi}] "
                f"(recommended [{rlo}, {rhi}]; 0 = factory value)"
            )


def profile_offsets(name: str) -> dict[str, int]:
    """Every settable bias's offset from factory under profile ``name`` (0 where the profile is silent)."""
    if name not in BIAS_PROFILES:
        raise ValueError(f"bias profile {name!r}: use one of {', '.join(BIAS_PROFILES)}")
    return {bias: BIAS_PROFILES[name].get(bias, 0) for bias in regs.BIASES}


def outside_recommended(offsets: dict[str, int]) -> list[str]:
    """The biases whose offset lies outside OpenEB's recommended range (each as ``name offset [lo, hi]``)."""
    out = []
    for name, offset in offsets.items():
        lo, hi = regs.BIASES[name].recommended
        if not lo <= offset <= hi:
            out.append(f"{name} {offset} [{lo}, {hi}]")
    return out

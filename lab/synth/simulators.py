"""The simulators a lab recording can be made with: ours (the product's training simulator) and
hesim-3d's H-ESIM, a second, independent one (``make eval-hesim``)."""

from __future__ import annotations

from darkread.lab.synth import hesim_sensor
from darkread.models.synth.recording import Simulator, simulate_events

SIMULATORS: tuple[str, ...] = ("darkread", "hesim")


def simulator_for(name: str) -> Simulator:
    """The simulator called ``name``; ValueError naming the choices, or why hesim-3d cannot run here."""
    if name == "darkread":
        return simulate_events
    if name == "hesim":
        if (reason := hesim_sensor.hesim_missing()) is not None:
            raise ValueError(f"--simulator hesim: {reason}")
        return hesim_sensor.simulate
    raise ValueError(f"--simulator {name!r}: use one of {', '.join(SIMULATORS)}")

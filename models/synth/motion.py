"""6-DoF motion of the head (and camera) relative to the page, as smooth random signals.

Every component is a sum of sinusoids with random frequencies and phases, so a trajectory is a
pure function of time (deterministic for a seed, cheap to evaluate at any rate):

* head drift / sway: 0.5-3 deg over seconds (0.05-0.5 Hz),
* physiological tremor: ~0.05-0.2 deg at 5-15 Hz (0.02-0.06 deg for a resting head, level ``still``),
* walking: vertical bob at the step frequency (1.6-2.2 Hz), lateral sway at half of it, pitch bob,
* hand-held page: slow sway in position and angle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MOTION_LEVELS: tuple[str, ...] = ("still", "normal", "walking")


@dataclass(frozen=True)
class Oscillators:
    """Sum of sinusoids: ``sum_k amp[k] * sin(2 pi freq[k] t + phase[k])`` per dimension."""

    amp: np.ndarray  # [K, D]
    freq: np.ndarray  # [K]
    phase: np.ndarray  # [K, D]

    def __call__(self, t_s: float | np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64)
        arg = 2 * np.pi * self.freq[:, None] * t.reshape(-1)[None, :]  # [K, N]
        out = np.einsum("kd,kdn->nd", self.amp, np.sin(arg[:, None, :] + self.phase[:, :, None]))
        return out[0] if t.ndim == 0 else out

    @staticmethod
    def random(
        rng: np.random.Generator, k: int, f_lo: float, f_hi: float, rms: np.ndarray | float, dims: int = 3
    ) -> Oscillators:
        """``k`` components in [f_lo, f_hi] Hz with a total RMS of ``rms`` per dimension."""
        rms = np.broadcast_to(np.asarray(rms, dtype=np.float64), (dims,))
        weights = rng.uniform(0.5, 1.5, (k, dims))
        # sum of k sinusoids of amplitude a has RMS a * sqrt(k / 2) when the weights are 1
        amp = weights / np.sqrt((weights**2).sum(axis=0) / 2) * rms
        freq = np.exp(rng.uniform(np.log(f_lo), np.log(f_hi), k))
        phase = rng.uniform(0, 2 * np.pi, (k, dims))
        return Oscillators(amp, freq, phase)

    @staticmethod
    def zero(dims: int = 3) -> Oscillators:
        return Oscillators(np.zeros((1, dims)), np.zeros(1), np.zeros((1, dims)))


@dataclass(frozen=True)
class Motion:
    """Perturbations around the base pose: head rotation, relative translation, page rotation."""

    level: str
    head_deg: tuple[Oscillators, ...]
    trans_m: tuple[Oscillators, ...]
    page_deg: tuple[Oscillators, ...]

    def at(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(head angles rad [3], translation m [3] in the camera frame, page angles rad [3])."""
        head = sum((o(t_s) for o in self.head_deg), np.zeros(3))
        trans = sum((o(t_s) for o in self.trans_m), np.zeros(3))
        page = sum((o(t_s) for o in self.page_deg), np.zeros(3))
        return np.radians(head), trans, np.radians(page)

    def max_speed_deg_s(self) -> float:
        """Upper bound of the head's angular speed (deg/s), for choosing the time step."""
        speed = 0.0
        for o in self.head_deg + self.page_deg:
            speed += float((np.abs(o.amp).max(axis=1) * 2 * np.pi * o.freq).sum())
        return speed


def random_motion(level: str, rng: np.random.Generator) -> Motion:
    if level not in MOTION_LEVELS:
        raise ValueError(f"unknown motion level {level!r}; use one of {', '.join(MOTION_LEVELS)}")
    if level == "still":  # head resting: the low end of physiological tremor
        tremor = Oscillators.random(rng, 6, 5.0, 15.0, rng.uniform(0.02, 0.06) / np.sqrt(2) * np.array([1.0, 1.0, 0.5]))
        drift = Oscillators.random(rng, 3, 0.05, 0.3, rng.uniform(0.2, 0.6) * np.array([1.0, 1.0, 0.3]))
        return Motion(level, (drift, tremor), (Oscillators.zero(),), (Oscillators.zero(),))
    tremor = Oscillators.random(rng, 6, 5.0, 15.0, rng.uniform(0.05, 0.2) / np.sqrt(2) * np.array([1.0, 1.0, 0.5]))
    drift = Oscillators.random(rng, 4, 0.05, 0.5, rng.uniform(0.5, 2.0) * np.array([1.0, 0.8, 0.3]))
    page_rot = Oscillators.random(rng, 3, 0.2, 1.0, rng.uniform(0.2, 0.8) * np.array([1.0, 1.0, 0.5]))
    page_pos = Oscillators.random(rng, 3, 0.2, 1.0, rng.uniform(0.001, 0.004) * np.array([1.0, 1.0, 0.5]))
    if level == "normal":
        return Motion(level, (drift, tremor), (page_pos,), (page_rot,))
    step_hz = rng.uniform(1.6, 2.2)
    bob_amp = rng.uniform(0.004, 0.012)
    bob = Oscillators(
        amp=np.array([[0.0, bob_amp, 0.3 * bob_amp], [0.5 * bob_amp, 0.0, 0.0]]),
        freq=np.array([step_hz, step_hz / 2]),
        phase=rng.uniform(0, 2 * np.pi, (2, 3)),
    )
    pitch_amp = rng.uniform(0.3, 1.0)
    head_bob = Oscillators(
        amp=np.array([[pitch_amp, 0.0, 0.0], [0.0, 0.5 * pitch_amp, 0.4 * pitch_amp]]),
        freq=np.array([step_hz, step_hz / 2]),
        phase=rng.uniform(0, 2 * np.pi, (2, 3)),
    )
    page_rot_w = Oscillators.random(rng, 3, 0.3, 2.0, rng.uniform(0.5, 1.5) * np.array([1.0, 1.0, 0.5]))
    return Motion(level, (drift, tremor, head_bob), (page_pos, bob), (page_rot_w,))

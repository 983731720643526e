"""6-DoF motion of the head (and camera) relative to the page, as smooth random signals.

Every component is a sum of sinusoids with random frequencies and phases, so a trajectory is a
pure function of time (deterministic for a seed, cheap to evaluate at any rate):

* head drift / sway: 0.5-3 deg over seconds (0.05-0.5 Hz),
* physiological tremor: ~0.05-0.2 deg at 5-15 Hz (0.02-0.06 deg for a resting head, level ``still``),
* walking: vertical bob at the step frequency (1.6-2.2 Hz), lateral sway at half of it, pitch bob,
* hand-held page: slow sway in position and angle.

These are the ``standard`` regime's draws (what training saw and the suite was made with). The
``grounded`` regime (:func:`grounded_motion`, docs/head_motion_model.md) takes the head's tremor and
reading motion from measurements, each with its spread as a band; ``quiet``, ``central`` and
``strong`` put every band at its low end, centre or high end (the band's ends for the suite).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MOTION_LEVELS: tuple[str, ...] = ("still", "normal", "walking")
MOTION_REGIMES: tuple[str, ...] = ("standard", "grounded", "quiet", "central", "strong")


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


def random_motion(level: str, rng: np.random.Generator, regime: str = "standard") -> Motion:
    """A head motion of ``level`` drawn under ``regime`` (``standard``: today's draws, unchanged)."""
    if level not in MOTION_LEVELS:
        raise ValueError(f"unknown motion level {level!r}; use one of {', '.join(MOTION_LEVELS)}")
    if regime != "standard":
        return grounded_motion(level, rng, regime)
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


@dataclass(frozen=True)
class Band:
    """A measured quantity's plausible range and its central value (docs/head_motion_model.md)."""

    lo: float
    central: float
    hi: float

    def pick(self, regime: str, rng: np.random.Generator) -> float:
        """The band's value under a grounded regime: its low end (``quiet``), centre, high end
        (``strong``), or a log-uniform draw across it (``grounded``)."""
        if regime == "grounded":
            return float(np.exp(rng.uniform(np.log(self.lo), np.log(self.hi))))
        return {"quiet": self.lo, "central": self.central, "strong": self.hi}[regime]


# The grounded regime's bands: peak amplitudes in degrees per axis, frequencies in Hz. Where each
# number comes from, and which are only bounded rather than measured: docs/head_motion_model.md.
TREMOR_DEG = Band(0.02, 0.04, 0.083)  # Elble et al. 2016, gyroscope fit at tremor rating 0 (0.04) to 0.5
TREMOR_HZ = (8.0, 12.0)  # physiological tremor
READING_SWEEP_DEG = Band(0.35, 0.52, 0.67)  # yaw along a line: 4.7 % of a 15-28.6 deg line (Proudlock et al. 2003)
LINE_HZ = (0.25, 0.8)  # one line per 1.25-4 s (the suite's lines; not measured on readers)
READING_DESCENT_DEG = Band(0.3, 0.6, 1.4)  # pitch down the page: 28.7 % of a 2-10 deg text block (Proudlock et al. 2003)
PAGE_HZ = (0.03, 0.1)  # one page of text per 10-30 s (not measured on readers)
ROLL_SHARE = 0.3  # roll as a share of yaw: no measurement found (the standard draws' ratio)
GAIT_PITCH_DEG = Band(0.3, 0.55, 1.0)  # not measured: the standard draws', below Grossman et al.'s 90 deg/s bound
STEP_HZ = (1.6, 2.2)  # pitch at the step frequency, yaw at half of it (Grossman et al. 1988)


def grounded_motion(level: str, rng: np.random.Generator, regime: str = "grounded") -> Motion:
    """A reader's head motion from measurements: tremor, the head's share of the reading gaze
    (sweeping along each line, descending the page) and, walking, the gait's pitch and yaw.

    ``still`` is a seated reader with the page on a table (Proudlock et al.'s condition), ``normal``
    one holding the page (its sway: the standard draws, not measured), ``walking`` adds the gait.
    """
    if regime not in MOTION_REGIMES or regime == "standard":
        raise ValueError(f"motion regime {regime!r}: a grounded one of {', '.join(MOTION_REGIMES[1:])}")
    tremor_deg = TREMOR_DEG.pick(regime, rng)
    tremor = Oscillators.random(rng, 6, *TREMOR_HZ, tremor_deg / np.sqrt(2) * np.array([1.0, 1.0, 0.5]))
    sweep_deg = READING_SWEEP_DEG.pick(regime, rng)
    line_hz = float(np.exp(rng.uniform(np.log(LINE_HZ[0]), np.log(LINE_HZ[1]))))
    sweep = Oscillators(  # [pitch, yaw, roll]
        amp=np.array([[0.0, sweep_deg, ROLL_SHARE * sweep_deg]]), freq=np.array([line_hz]), phase=rng.uniform(0, 2 * np.pi, (1, 3))
    )
    descent = Oscillators(
        amp=np.array([[READING_DESCENT_DEG.pick(regime, rng), 0.0, 0.0]]),
        freq=np.array([float(rng.uniform(*PAGE_HZ))]),
        phase=rng.uniform(0, 2 * np.pi, (1, 3)),
    )
    head: tuple[Oscillators, ...] = (descent, sweep, tremor)
    if level == "still":
        return Motion(level, head, (Oscillators.zero(),), (Oscillators.zero(),))
    page_rot = Oscillators.random(rng, 3, 0.2, 1.0, rng.uniform(0.2, 0.8) * np.array([1.0, 1.0, 0.5]))
    page_pos = Oscillators.random(rng, 3, 0.2, 1.0, rng.uniform(0.001, 0.004) * np.array([1.0, 1.0, 0.5]))
    if level == "normal":
        return Motion(level, head, (page_pos,), (page_rot,))
    step_hz = rng.uniform(*STEP_HZ)
    pitch_deg = GAIT_PITCH_DEG.pick(regime, rng)
    gait = Oscillators(
        amp=np.array([[pitch_deg, 0.0, 0.0], [0.0, 0.5 * pitch_deg, 0.4 * pitch_deg]]),
        freq=np.array([step_hz, step_hz / 2]),
        phase=rng.uniform(0, 2 * np.pi, (2, 3)),
    )
    bob_amp = rng.uniform(0.004, 0.012)  # vertical bob (m): the standard draws'
    bob = Oscillators(
        amp=np.array([[0.0, bob_amp, 0.3 * bob_amp], [0.5 * bob_amp, 0.0, 0.0]]),
        freq=np.array([step_hz, step_hz / 2]),
        phase=rng.uniform(0, 2 * np.pi, (2, 3)),
    )
    return Motion(level, (*head, gait), (page_pos, bob), (page_rot,))

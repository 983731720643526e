"""The head's motion from the glasses' gyroscope: a ``KnownHeadMotion`` that needs no events.

The camera sits on the head, and a page at reading distance is far compared with how far the
camera moves while the head turns, so to first order the page moves in the sensor by the head's
rotation alone: a pure-rotation homography ``K R K^-1`` (translation and the page's own motion are
not seen; they are what the event tracker and the deblur's search still take). The gyroscope's
angular velocity (device frame = CPF, ``edge.io.imu_csv``) is rotated into the event camera by
``calibration.json``'s ``T_event_cpf``, its bias removed, and integrated: the camera's rotation
since the stream began, as a rotation vector summed sample by sample (small-angle: the rotations
between two times the edge compares are a few degrees at most). A rotation ``theta`` of the camera
moves a fixed direction ``d`` (camera frame) to ``exp(-[theta]x) d``; projected through the
intrinsics (with distortion) that is the scene's shift at a pixel.

The bias is estimated online: the mean angular velocity over ``bias_window_us`` of the samples
where the head is still (the mean over ``still_span_us`` around them is under ``still_rad_s``),
shrunk towards zero as if ``bias_prior_us`` more of still samples had read zero. A reading head's
slow drift passes as still too, and over a few seconds it does not average out: taken whole, it
was learnt as bias within 100 ms and the page's real motion erased (docs/head_motion.md).

Samples further apart than ``gap_us`` are a gap: nothing is integrated across it, and for
``trust_us`` after it the motion is unknown (``healthy`` is False): the edge then falls back to
the event tracker and the deblur's own search. So it does while the head walks: a walking head
pitches at the step rate (``step_band_rms``), and the page in the hand bobs against it, which no
gyroscope sees.

Pure functions of arrays at the core; ``ImuHeadMotion`` holds the integrated track, extended by a
whole file (replay) or by the live feed's batches (``edge.sources.imu_feed``), under a lock.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np

from darkread.edge.deblur import moved_to
from darkread.edge.events import Events
from darkread.edge.io.calibration import Calibration
from darkread.edge.io.imu_csv import ImuTrack


@dataclass(frozen=True)
class ImuMotionConfig:
    gap_us: int = 20_000  # samples further apart: a gap (Aria's IMUs sample every 1-1.25 ms)
    trust_us: int = 100_000  # after a gap (or before the first sample) the motion stays unknown this long
    max_age_us: int = 50_000  # a live stream's newest sample answers for this long after it
    still_span_us: int = 100_000  # the head is still when its mean angular velocity over this span ...
    still_rad_s: float = 0.035  # ... is below this (2 deg/s: above a calibrated MEMS bias, below a turning head)
    bias_window_us: int = 10_000_000  # the bias: the mean of the still samples over this long before ...
    bias_prior_us: int = 5_000_000  # ... shrunk towards zero as if this long of still samples had read zero
    smear_radius_px: float = 2.0  # the deblur searches this far around the predicted smear
    keep_us: int = 30_000_000  # a live stream keeps this much history (a replayed file keeps all)
    # walking: the head pitches at the step rate, and a held page bobs against it, which no
    # gyroscope sees (docs/head_motion.md); the edge then measures the motion from the events
    step_band_hz: tuple[float, float] = (1.4, 2.8)  # walking cadence, 1.6-2.2 steps/s, with margin
    step_span_us: int = 2_000_000  # the spectrum's span: ~3 steps
    step_min_span_us: int = 500_000  # less data than this (the stream's start) decides nothing: not trusted
    step_rad_s: float = 0.0175  # 1 deg/s RMS in the step band: a walking head (reading seated or standing: < 0.5)
    step_block_us: int = 100_000  # the decision is refreshed this often
    step_hold_us: int = 1_000_000  # and, once walking, held this long after the last block that said so


# -- rotations, vectorised ------------------------------------------------------------------------

def rotate(vectors: np.ndarray, rotvecs: np.ndarray) -> np.ndarray:
    """``vectors`` [n, 3] (or one [3]) rotated by the rotation vectors ``rotvecs`` [n, 3] (Rodrigues)."""
    rotvecs = np.asarray(rotvecs, np.float64).reshape(-1, 3)
    v = np.broadcast_to(np.asarray(vectors, np.float64), rotvecs.shape)
    angle = np.linalg.norm(rotvecs, axis=1, keepdims=True)
    safe = np.where(angle > 0, angle, 1.0)
    k = rotvecs / safe
    cos, sin = np.cos(angle), np.sin(angle)
    return v * cos + np.cross(k, v) * sin + k * np.sum(k * v, axis=1, keepdims=True) * (1.0 - cos)


def rotation_matrices(rotvecs: np.ndarray) -> np.ndarray:
    """[n, 3, 3] rotation matrices of rotation vectors [n, 3] (what ``cv2.Rodrigues`` gives, for many)."""
    rotvecs = np.asarray(rotvecs, np.float64).reshape(-1, 3)
    eye = np.broadcast_to(np.eye(3), (rotvecs.shape[0], 3, 3))
    return np.stack([rotate(eye[:, :, j], rotvecs) for j in range(3)], axis=2)


def rotation_vectors(matrices: np.ndarray) -> np.ndarray:
    """[n, 3] rotation vectors of rotation matrices [n, 3, 3] (angles below pi)."""
    m = np.asarray(matrices, np.float64).reshape(-1, 3, 3)
    cos = np.clip((np.trace(m, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    axis = np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1)
    sin = np.sin(angle)
    scale = np.where(sin > 1e-12, angle / np.where(sin > 1e-12, 2.0 * sin, 1.0), 0.5)  # (small angles: axis ~ 2 theta)
    return axis * scale[:, None]


def quaternions_xyzw(matrices: np.ndarray) -> np.ndarray:
    """[n, 4] unit quaternions (x, y, z, w; w >= 0) of rotation matrices [n, 3, 3]."""
    rotvecs = rotation_vectors(matrices)
    angle = np.linalg.norm(rotvecs, axis=1, keepdims=True)
    k = rotvecs / np.where(angle > 0, angle, 1.0)
    return np.concatenate([k * np.sin(angle / 2), np.cos(angle / 2)], axis=1)


# -- the gyroscope's track ------------------------------------------------------------------------

def cumulative(values: np.ndarray) -> np.ndarray:
    """[n + 1, d]: the running sums of ``values`` [n, d] with a leading zero row."""
    return np.concatenate([np.zeros((1,) + values.shape[1:]), np.cumsum(values, axis=0)])


def still_at(t_us: np.ndarray, cum_omega: np.ndarray, index: np.ndarray, cfg: ImuMotionConfig = ImuMotionConfig()) -> np.ndarray:
    """bool [len(index)]: the head was still at those samples, its mean angular velocity over the
    ``still_span_us`` up to each small (``cum_omega``: the track's ``cumulative``, causal)."""
    first = np.searchsorted(t_us, t_us[index] - cfg.still_span_us, side="right")
    mean = (cum_omega[index + 1] - cum_omega[first]) / np.maximum(index + 1 - first, 1)[:, None]
    return np.linalg.norm(mean, axis=1) < cfg.still_rad_s


def bias_at(t_us: np.ndarray, cum_still: np.ndarray, cum_count: np.ndarray, index: np.ndarray, window_us: int,
            prior_us: int = 0) -> np.ndarray:
    """[len(index), 3]: the bias at those samples, the mean of the still samples over ``window_us`` up
    to each (0 before any), shrunk towards zero as if ``prior_us`` more of still samples (at the
    stream's rate over the window) had read zero; ``cum_still`` and ``cum_count`` the ``cumulative``
    of the still samples' velocity (the others 0) and of how many were still."""
    first = np.searchsorted(t_us, t_us[index] - window_us, side="right")
    count = cum_count[index + 1] - cum_count[first]
    span = np.maximum(t_us[index] - t_us[first], 1).astype(np.float64)
    prior = prior_us * (index + 1 - first) / span  # (in samples, at the stream's own rate)
    return np.where(count > 0, (cum_still[index + 1] - cum_still[first]) / np.maximum(count + prior[:, None], 1), 0.0)


def still_samples(t_us: np.ndarray, omega: np.ndarray, cfg: ImuMotionConfig = ImuMotionConfig()) -> np.ndarray:
    """bool [n]: the head was still at each sample of a whole track (``still_at``)."""
    return still_at(t_us, cumulative(omega), np.arange(t_us.shape[0]), cfg)


def running_bias(t_us: np.ndarray, omega: np.ndarray, still: np.ndarray, window_us: int) -> np.ndarray:
    """[n, 3]: each sample's bias over a whole track (``bias_at``)."""
    weight = still.astype(np.float64)[:, None]
    return bias_at(t_us, cumulative(omega * weight), cumulative(weight), np.arange(t_us.shape[0]), window_us)


def integrate(t_us: np.ndarray, omega: np.ndarray, gap_us: int) -> np.ndarray:
    """[n, 3]: the rotation vector summed from the first sample (trapezoids; nothing across a gap)."""
    dt = np.diff(t_us).astype(np.float64) * 1e-6
    steps = 0.5 * (omega[1:] + omega[:-1]) * dt[:, None]
    steps[np.diff(t_us) > gap_us] = 0.0
    return np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])


STEP_BLOCKS_AT_ONCE = 256  # spectra taken together: 256 spans of 2 s at 1 kHz, 3 axes, about 12 MB


def step_band_rms(t_us: np.ndarray, omega: np.ndarray, block_ends_us: np.ndarray,
                  cfg: ImuMotionConfig = ImuMotionConfig()) -> np.ndarray:
    """[n_blocks] rad/s: the angular velocity's RMS (all axes) in the walking cadence's band over the
    ``step_span_us`` before each block end, or what of it the samples cover (at the stream's start);
    NaN where they cover less than ``step_min_span_us``. Each span resampled to 1 kHz, its linear
    trend removed (the slow reading drift would leak into the band), a Hann window, one FFT."""
    out = np.full(block_ends_us.shape[0], np.nan)
    covered = np.minimum(block_ends_us - int(t_us[0]), cfg.step_span_us) // 1000
    t_float = t_us.astype(np.float64)
    for n in np.unique(covered[covered >= cfg.step_min_span_us // 1000]):  # (one length for all but the first blocks)
        same = np.flatnonzero(covered == n)
        for start in range(0, same.shape[0], STEP_BLOCKS_AT_ONCE):  # memory bounded however long the track
            rows = same[start:start + STEP_BLOCKS_AT_ONCE]
            grid = block_ends_us[rows, None].astype(np.float64) - 1000.0 * np.arange(n - 1, -1, -1)[None, :]
            spans = np.stack([np.interp(grid, t_float, omega[:, k]) for k in range(3)], axis=2)
            out[rows] = _band_rms(spans, cfg.step_band_hz)
    return out


def _band_rms(spans: np.ndarray, band_hz: tuple[float, float]) -> np.ndarray:
    """[m] RMS in ``band_hz`` of ``spans`` [m, n, 3] sampled at 1 kHz (linear trend removed, Hann window)."""
    n = spans.shape[1]
    x = np.linspace(-1.0, 1.0, n)[None, :, None]
    slope = (spans * x).sum(axis=1, keepdims=True) / (x ** 2).sum()
    detrended = spans - spans.mean(axis=1, keepdims=True) - slope * x
    window = np.hanning(n)
    spectrum = np.fft.rfft(detrended * window[None, :, None], axis=1)
    freq = np.fft.rfftfreq(n, 1e-3)
    band = (freq >= band_hz[0]) & (freq <= band_hz[1])
    power = (np.abs(spectrum[:, band]) ** 2).sum(axis=(1, 2)) * 2.0 / (np.sum(window ** 2) * n)
    return np.sqrt(power)


def shift_px(calibration: Calibration, centre_px: tuple[float, float], rotvecs: np.ndarray) -> np.ndarray:
    """[n, 2]: where the scene point seen at ``centre_px`` goes in the sensor when the camera turns by
    each rotation vector (camera frame), minus ``centre_px``: the pure-rotation homography at that pixel."""
    ray = calibration.unproject(np.asarray([centre_px], np.float64))[0]
    direction = np.array([ray[0], ray[1], 1.0])
    moved = rotate(direction, -np.asarray(rotvecs, np.float64).reshape(-1, 3))
    return calibration.project(moved) - np.asarray(centre_px, np.float64)


def shift_px_one(calibration: Calibration, centre_px: tuple[float, float], rotvec: np.ndarray) -> tuple[float, float]:
    """``shift_px`` for one rotation vector, in plain floats: the same arithmetic in the same order
    (Rodrigues as ``rotate``, the projection as ``project_point``), for the per-frame predictions
    where numpy's per-call cost is many times the work."""
    ray = calibration.unproject(np.asarray([centre_px], np.float64))[0]
    v0, v1, v2 = float(ray[0]), float(ray[1]), 1.0
    r0, r1, r2 = (-float(value) for value in np.asarray(rotvec, np.float64).reshape(3))
    angle = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    safe = angle if angle > 0 else 1.0
    k0, k1, k2 = r0 / safe, r1 / safe, r2 / safe
    cos, sin = math.cos(angle), math.sin(angle)
    dot = k0 * v0 + k1 * v1 + k2 * v2
    moved = (v0 * cos + (k1 * v2 - k2 * v1) * sin + k0 * dot * (1.0 - cos),
             v1 * cos + (k2 * v0 - k0 * v2) * sin + k1 * dot * (1.0 - cos),
             v2 * cos + (k0 * v1 - k1 * v0) * sin + k2 * dot * (1.0 - cos))
    pixel = calibration.project_point(*moved)
    if pixel is None:
        return math.nan, math.nan
    return pixel[0] - float(centre_px[0]), pixel[1] - float(centre_px[1])


KEEP_SLACK = 2  # a live stream's history is trimmed back to ``keep_us`` once it holds this many times as much


class Rows:
    """A growable array of rows, appended at the end and trimmed from the front, both amortised: a
    live stream appends a datagram's samples 50 times a second, and copying the whole history held
    at each would cost more than everything else the gyroscope does."""

    def __init__(self, first: np.ndarray) -> None:
        self._buf = np.array(first, copy=True)
        self._start, self._end = 0, self._buf.shape[0]

    @property
    def view(self) -> np.ndarray:
        return self._buf[self._start:self._end]

    def append(self, rows: np.ndarray) -> None:
        n = rows.shape[0]
        if self._end + n > self._buf.shape[0]:
            held = self._end - self._start
            grown = np.empty((max(2 * (held + n), 1024),) + self._buf.shape[1:], self._buf.dtype)
            grown[:held] = self._buf[self._start:self._end]
            self._buf, self._start, self._end = grown, 0, held
        self._buf[self._end:self._end + n] = rows
        self._end += n

    def drop_front(self, n: int) -> None:
        self._start += n


class ImuHeadMotion:
    """``KnownHeadMotion`` from the gyroscope, with the deblur's predicted smear (``smear_prior``).

    Times asked for are on the event clock; samples arrive on the device clock
    (``t_event = t_device + calibration.gaze_to_event_time_offset_us``, the gaze's clock).
    ``healthy(t)`` says whether the motion at ``t`` is known: the edge falls back to the events where not.
    """

    def __init__(self, calibration: Calibration, cfg: ImuMotionConfig = ImuMotionConfig(), *,
                 clock_offset_us: int | None = None, live: bool = False) -> None:
        self.calibration = calibration
        self.cfg = cfg
        self.clock_offset_us = int(calibration.gaze_to_event_time_offset_us if clock_offset_us is None else clock_offset_us)
        self.live = live
        self.smear_radius_px = cfg.smear_radius_px
        self._rotation = np.asarray(calibration.T_event_cpf, np.float64)[:3, :3]  # device (CPF) -> event camera
        self._centre = (float(calibration.cx), float(calibration.cy))
        self._lock = threading.Lock()
        self._t_rows = Rows(np.zeros(0, np.int64))  # event clock
        self._t_float_rows = Rows(np.zeros(0))  # the same as ``np.interp`` takes it (each question would copy it)
        self._raw_rows = Rows(np.zeros((0, 3)))  # device frame, as received
        self._theta_rows = [Rows(np.zeros(0)) for _ in range(3)]  # camera frame, integrated: one per axis, contiguous
        # cumulative sums with a leading row, for the moving means: the angular velocity, the still
        # samples' and how many were still (``still_samples``, ``running_bias``, one sample at a time)
        self._cum_raw = Rows(np.zeros((1, 3)))
        self._cum_still = Rows(np.zeros((1, 3)))
        self._cum_count = Rows(np.zeros((1, 1)))
        self._last_corrected = np.zeros(3)  # the newest sample's bias-corrected velocity (camera frame)
        self._gaps = np.zeros(0, np.int64)  # event times where a gap ended (the first sample after it)
        self._step_t = np.zeros(0, np.int64)  # block ends (event clock) where walking was decided ...
        self._walked = np.zeros(0, bool)  # ... whether the head walked ...
        self._unknown = np.zeros(0, bool)  # ... or too little was known to say
        self.received = 0

    @property
    def _t(self) -> np.ndarray:
        return self._t_rows.view

    @property
    def _raw(self) -> np.ndarray:
        return self._raw_rows.view

    @property
    def _t_float(self) -> np.ndarray:
        return self._t_float_rows.view

    @property
    def _theta_columns(self) -> list[np.ndarray]:
        return [rows.view for rows in self._theta_rows]

    @classmethod
    def of_track(cls, track: ImuTrack, calibration: Calibration, cfg: ImuMotionConfig = ImuMotionConfig(),
                 clock_offset_us: int | None = None) -> ImuHeadMotion:
        motion = cls(calibration, cfg, clock_offset_us=clock_offset_us)
        motion.extend(track.t_us, track.omega)
        return motion

    # -- samples in ---------------------------------------------------------------------------------
    def extend(self, t_device_us: np.ndarray, omega_device: np.ndarray) -> None:
        """Append samples (device clock, rad/s in the device frame); older than the newest held are
        dropped, and so are samples that are not finite (one would stay in the running sums held)."""
        t = np.asarray(t_device_us, np.int64).reshape(-1) + self.clock_offset_us
        omega = np.asarray(omega_device, np.float64).reshape(-1, 3)
        finite = np.isfinite(omega).all(axis=1)
        t, omega = t[finite], omega[finite]
        with self._lock:
            if self._t.shape[0]:
                newer = t > self._t[-1]
                t, omega = t[newer], omega[newer]
            keep = np.concatenate([[True], np.diff(t) > 0]) if t.shape[0] else np.zeros(0, bool)
            t, omega = t[keep], omega[keep]
            if t.shape[0] == 0:
                return
            n_old = self._t.shape[0]
            self._t_rows.append(t)
            self._t_float_rows.append(t.astype(np.float64))
            self._raw_rows.append(omega)
            all_t = self._t
            # the bias (``running_bias`` of ``still_samples``, causal) of each new sample from the
            # cumulative sums held: the same arithmetic as over the whole track, a datagram at a time
            index = np.arange(n_old, n_old + t.shape[0])
            cum_raw = self._append_cumulative(self._cum_raw, omega)
            weight = still_at(all_t, cum_raw, index, self.cfg).astype(np.float64)[:, None]
            cum_still = self._append_cumulative(self._cum_still, omega * weight)
            cum_count = self._append_cumulative(self._cum_count, weight)
            bias = bias_at(all_t, cum_still, cum_count, index, self.cfg.bias_window_us, self.cfg.bias_prior_us)
            corrected = (omega - bias) @ self._rotation.T
            # integrated onto the newest angle held (from the newest sample: its trapezoid)
            if n_old:
                theta = integrate(all_t[n_old - 1:], np.concatenate([self._last_corrected[None, :], corrected]), self.cfg.gap_us)[1:]
                theta += np.array([float(rows.view[-1]) for rows in self._theta_rows])
            else:
                theta = integrate(t, corrected, self.cfg.gap_us)
            self._last_corrected = corrected[-1]
            for k, rows in enumerate(self._theta_rows):
                rows.append(theta[:, k])
            steps = np.diff(all_t[max(n_old - 1, 0):])
            ended = all_t[max(n_old - 1, 0) + 1:][steps > self.cfg.gap_us]
            self._gaps = np.concatenate([self._gaps, ended])
            self._decide_walking()
            self.received += int(t.shape[0])
            if self.live and self._t[-1] - self._t[0] > KEEP_SLACK * self.cfg.keep_us:  # amortised trim
                first_kept = int(np.searchsorted(self._t, self._t[-1] - self.cfg.keep_us))
                for rows in (self._t_rows, self._t_float_rows, self._raw_rows, self._cum_raw, self._cum_still,
                             self._cum_count, *self._theta_rows):
                    rows.drop_front(first_kept)
                self._gaps = self._gaps[self._gaps >= self._t[0]]
                kept = self._step_t >= self._t[0]
                self._step_t, self._walked, self._unknown = self._step_t[kept], self._walked[kept], self._unknown[kept]

    @staticmethod
    def _append_cumulative(rows: Rows, values: np.ndarray) -> np.ndarray:
        """Append ``values``' running sums, continuing the held ones (one addition after another, as
        ``np.cumsum`` over the whole track adds them); the sums held, with their leading row."""
        rows.append(np.cumsum(np.concatenate([rows.view[-1:], values]), axis=0)[1:])
        return rows.view

    def _decide_walking(self) -> None:
        """Walking or not at each new block end up to the newest sample (``step_band_rms``)."""
        block = self.cfg.step_block_us
        start = int(self._step_t[-1]) + block if self._step_t.shape[0] else (int(self._t[0]) // block + 1) * block
        ends = np.arange(start, int(self._t[-1]) + 1, block, dtype=np.int64)
        if ends.shape[0] == 0:
            return
        # (the samples the new blocks' spans reach, and the stream's first one while it is short)
        tail = max(int(np.searchsorted(self._t, int(ends[0]) - self.cfg.step_span_us, side="right")) - 2, 0)
        rms = step_band_rms(self._t[tail:], self._raw[tail:], ends, self.cfg)
        self._step_t = np.concatenate([self._step_t, ends])
        self._walked = np.concatenate([self._walked, rms > self.cfg.step_rad_s])
        self._unknown = np.concatenate([self._unknown, np.isnan(rms)])

    # -- what the edge asks -------------------------------------------------------------------------
    @property
    def available(self) -> bool:
        """Whether any sample has arrived."""
        return self._t.shape[0] > 0

    @property
    def span_us(self) -> tuple[int, int] | None:
        """(first, newest) sample times on the event clock; None with fewer than two samples."""
        with self._lock:
            return None if self._t.shape[0] < 2 else (int(self._t[0]), int(self._t[-1]))

    def healthy(self, t_us: int) -> bool:
        """The rotation at ``t_us`` is known: inside the samples (a live stream's newest answers
        ``max_age_us`` on), and neither the stream's start nor a gap's end lies within ``trust_us`` before."""
        with self._lock:
            return self._healthy(int(t_us))

    def _healthy(self, t_us: int) -> bool:
        t = self._t
        if t.shape[0] < 2 or t_us < t[0] + self.cfg.trust_us or t_us > t[-1] + (self.cfg.max_age_us if self.live else 0):
            return False
        k = int(np.searchsorted(self._gaps, t_us, side="right"))
        if k and t_us - int(self._gaps[k - 1]) < self.cfg.trust_us:
            return False
        nxt = int(np.searchsorted(t, t_us))  # inside a gap: the samples around it are far apart
        if 0 < nxt < t.shape[0] and t[nxt] - t[nxt - 1] > self.cfg.gap_us:
            return False
        return not self._walking(t_us)

    def _walking(self, t_us: int) -> bool:
        """The last block decided by ``t_us`` (or one within ``step_hold_us`` before it) said walking,
        or the last could not tell."""
        last = int(np.searchsorted(self._step_t, t_us, side="right"))
        if last == 0 or self._unknown[last - 1]:
            return True
        first = int(np.searchsorted(self._step_t, t_us - self.cfg.step_hold_us, side="right"))
        return bool(self._walked[min(first, last - 1):last].any())

    def walking(self, t_us: int) -> bool:
        """Whether the head walks at ``t_us`` (its pitch at the step rate), as far as the samples by then tell."""
        with self._lock:
            return self._walking(int(t_us))

    def rotation_at(self, t_us: np.ndarray) -> np.ndarray:
        """[n, 3]: the camera's integrated rotation vector at event times ``t_us`` (interpolated; held
        after the newest sample)."""
        with self._lock:
            return self._rotation_at(np.asarray(t_us, np.float64).reshape(-1))

    def _rotation_at(self, t: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(t, self._t_float, column) for column in self._theta_columns], axis=1)

    def scene_px(self, t_us: int) -> tuple[float, float] | None:
        """The scene's shift at the principal point since the stream's first sample (None where not healthy)."""
        with self._lock:
            if not self._healthy(int(t_us)):
                return None
            theta = self._rotation_at(np.array([float(t_us)]))
        return shift_px_one(self.calibration, self._centre, theta[0])

    def smear_prior(self, t_first_us: int, t_ref_us: int, centre_px: tuple[float, float]) -> tuple[float, float] | None:
        """The page's displacement at ``centre_px`` from ``t_first_us`` to ``t_ref_us`` (the deblur's
        smear), or None when the rotation is not known over that span."""
        with self._lock:
            if not (self._healthy(int(t_first_us)) and self._healthy(int(t_ref_us))):
                return None
            theta = self._rotation_at(np.array([float(t_first_us), float(t_ref_us)]))
        return shift_px_one(self.calibration, centre_px, theta[1] - theta[0])

    def warp(self, window: Events, origin: tuple[int, int], shape_hw: tuple[int, int]) -> Events:
        """``window``'s events moved by the rotation between each event and its newest (the window's
        centre's shift for every event); unchanged where the rotation is not known."""
        if window.shape[0] == 0:
            return window
        t_ref = int(window["t"][-1])
        with self._lock:
            if not (self._healthy(int(window["t"][0])) and self._healthy(t_ref)):
                return window
            theta = self._rotation_at(window["t"].astype(np.float64))
        centre = (origin[0] + shape_hw[1] / 2.0, origin[1] + shape_hw[0] / 2.0)
        d = shift_px(self.calibration, centre, theta[-1] - theta)
        return moved_to(window, window["x"] + d[:, 0], window["y"] + d[:, 1], origin, shape_hw)

    def summary(self) -> dict[str, float]:
        """Rate, duration and angular speed (deg/s) of the samples held."""
        with self._lock:
            t, raw = self._t, self._raw
        if t.shape[0] < 2:
            return {"samples": float(t.shape[0])}
        speed = np.degrees(np.linalg.norm(raw, axis=1))
        return {"samples": float(t.shape[0]), "rate_hz": 1e6 / float(np.median(np.diff(t))),
                "duration_s": float(t[-1] - t[0]) * 1e-6, "gaps": float(self._gaps.shape[0]),
                "speed_deg_s_p50": float(np.median(speed)), "speed_deg_s_p99": float(np.percentile(speed, 99))}


class JoinedSceneMotion:
    """The scene's offset from the gyroscope where it is healthy, else from the event tracker, as one
    continuous track; and how far the two disagree where both are known (the check).

    The two count from different origins, so each switch re-bases the source taken over: while both
    are known the gap between them is kept (``_tracker_shift``), the tracker continues the
    gyroscope's track with it, and the gyroscope, back, continues the tracker's. Where the source
    taken over is unknown too, the offset is unknown (None: the stitcher restarts its anchors).
    Asked in time order (the frames' times), by one thread.
    """

    def __init__(self) -> None:
        self._imu_shift = np.zeros(2)  # added to the gyroscope's offsets
        self._tracker_shift = np.zeros(2)  # added to the tracker's: (gyroscope + its shift) - tracker when last both were known
        self._using_imu = False
        self._last_both: tuple[np.ndarray, np.ndarray] | None = None  # (gyroscope, tracker) at the last time both were known

    def at(self, imu: tuple[float, float] | None,
           tracker: tuple[float, float] | None) -> tuple[tuple[float, float] | None, float | None]:
        """(the offset, the disagreement in px since the last time both were known, or None)."""
        disagreement = None
        if imu is not None:
            value = np.asarray(imu, np.float64) + self._imu_shift
            if not self._using_imu and tracker is not None:  # taking over from the tracker: continue its track
                continued = np.asarray(tracker, np.float64) + self._tracker_shift
                self._imu_shift += continued - value
                value = continued
            self._using_imu = True
            if tracker is not None:
                seen = np.asarray(tracker, np.float64)
                self._tracker_shift = value - seen
                if self._last_both is not None:
                    moved = (value - self._last_both[0]) - (seen - self._last_both[1])
                    disagreement = float(np.hypot(moved[0], moved[1]))
                self._last_both = (value, seen)
            return (float(value[0]), float(value[1])), disagreement
        self._using_imu = False
        self._last_both = None
        if tracker is None:
            return None, None
        value = np.asarray(tracker, np.float64) + self._tracker_shift
        return (float(value[0]), float(value[1])), None

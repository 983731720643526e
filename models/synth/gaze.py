"""Reading gaze: a scanpath over the printed lines and an eye tracker's view of it.

Scanpath (skilled adult readers; Rayner 1998, Slattery & Parker 2019): fixations of 150-500 ms
(mean ~230 ms), forward saccades of 7-9 letters lasting 20-40 ms, 10-15 % regressions, return
sweeps that often undershoot and are followed by a short corrective fixation, blinks every few
seconds. Positions are page texels; saccades follow a minimum-jerk profile.

Tracker: a constant per-session bias plus slow and fast noise (about 1-2 deg overall), a latency,
~60 Hz rows with jitter and missing rows, rows far off during blinks; written in the Gen1 vergence
schema on the device clock (yaw positive towards +x = the wearer's left).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from darkread.models.synth.page import PrintedPage

EYE_OFFSET_M = 0.0315
FIXATION_MIN_MS, FIXATION_MAX_MS = 150.0, 500.0


@dataclass
class Fixation:
    t0_s: float
    t1_s: float
    line: int
    char: float  # fractional character index along the line
    x: float  # page texels
    y: float
    kind: str  # "start", "forward", "regression", "sweep", "corrective"


@dataclass
class Scanpath:
    fixations: list[Fixation]
    blinks: np.ndarray  # [n, 2] start, end (s)
    t: np.ndarray  # dense time grid (s)
    xy: np.ndarray  # [len(t), 2] gaze position in texels

    def position(self, t_s: np.ndarray | float) -> np.ndarray:
        """Gaze position in texels at times ``t_s`` ([N, 2], or [2] for a scalar)."""
        t = np.asarray(t_s, dtype=np.float64)
        out = np.stack([np.interp(t.ravel(), self.t, self.xy[:, 0]), np.interp(t.ravel(), self.t, self.xy[:, 1])], 1)
        return out[0] if t.ndim == 0 else out

    def first_pass_end_s(self) -> float:
        """When the reader leaves the last line for the first time (the page read once), or inf."""
        last = max(f.line for f in self.fixations)
        for before, after in zip(self.fixations, self.fixations[1:]):
            if before.line == last and after.kind == "sweep":
                return before.t1_s
        return math.inf

    def in_blink(self, t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64)
        inside = np.zeros(t.shape, dtype=bool)
        for b0, b1 in self.blinks:
            inside |= (t >= b0) & (t < b1)
        return inside


def _fixation_ms(rng: np.random.Generator, short: bool = False) -> float:
    if short:  # fixation after an undershooting return sweep
        return float(rng.uniform(138.0, 176.0))
    return float(np.clip(rng.lognormal(math.log(215.0), 0.3), FIXATION_MIN_MS, FIXATION_MAX_MS))


def saccade_ms(amplitude_deg: float, forward: bool) -> float:
    """Main sequence: ~21 ms + 2.2 ms per degree (forward saccades kept within 20-40 ms)."""
    d = 21.0 + 2.2 * abs(amplitude_deg)
    return float(np.clip(d, 20.0, 40.0) if forward else np.clip(d, 20.0, 80.0))


def reading_scanpath(
    page: PrintedPage,
    duration_s: float,
    deg_per_texel: float,
    rng: np.random.Generator,
    *,
    start_line: int = 0,
    regression_p: float = 0.12,
    dt_s: float = 0.001,
) -> Scanpath:
    """A reading scanpath over ``page`` lasting at least ``duration_s`` (page re-read when finished)."""
    n_lines = len(page.lines)
    char_w = [np.diff(cx).mean() if len(cx) > 1 else page.xheight_tex for cx in page.char_x]

    def position(line: int, char: float) -> tuple[float, float]:
        cx = page.char_x[line]
        x = float(np.interp(char, np.arange(len(cx)), cx, left=cx[0] + char * char_w[line], right=cx[-1] + (char - len(cx) + 1) * char_w[line]))
        y = float(page.line_y[line] + rng.normal(0, 0.15 * page.xheight_tex))
        return x, y

    fixations: list[Fixation] = []
    saccades: list[tuple[float, float]] = []  # (start, duration) of the saccade into each fixation
    t = 0.0
    line = int(start_line) % n_lines
    char = float(rng.uniform(1.0, 4.0))
    kind = "start"
    while t < duration_s:
        x, y = position(line, char)
        dur = _fixation_ms(rng, short=(kind == "sweep_under")) / 1000.0
        fixations.append(Fixation(t, t + dur, line, char, x, y, "sweep" if kind == "sweep_under" else kind))
        t += dur
        n_chars = len(page.lines[line])
        if kind == "sweep_under":  # corrective saccade leftwards to the line start
            new_line, new_char, kind = line, float(rng.uniform(1.0, 3.0)), "corrective"
        elif char >= n_chars - rng.uniform(4.0, 6.0):  # return sweep to the next line
            new_line = (line + 1) % n_lines
            if rng.random() < 0.7:
                new_char, kind = float(rng.uniform(6.0, 10.0)), "sweep_under"
            else:
                new_char, kind = float(rng.uniform(2.0, 5.0)), "sweep"
        elif rng.random() < regression_p and char > 3:
            new_line, new_char, kind = line, max(0.0, char - float(rng.uniform(3.0, 8.0))), "regression"
        else:
            step = float(np.clip(rng.normal(8.0, 0.6), 6.5, 9.5))
            new_line, new_char, kind = line, char + step + float(rng.normal(0, 0.3)), "forward"
        nx, ny = position(new_line, min(new_char, len(page.lines[new_line]) - 1.0))
        amp_deg = math.hypot(nx - x, ny - y) * deg_per_texel
        sdur = saccade_ms(amp_deg, forward=(kind == "forward")) / 1000.0
        saccades.append((t, sdur))
        t += sdur
        line, char = new_line, min(new_char, len(page.lines[new_line]) - 1.0)

    return trajectory(fixations, saccades, t, rng, dt_s)


def trajectory(fixations: list[Fixation], saccades: list[tuple[float, float]], t_end_s: float,
               rng: np.random.Generator, dt_s: float = 0.001) -> Scanpath:
    """The dense gaze track of a fixation sequence: still during fixations, a minimum-jerk
    movement over each saccade ((start, duration) of the saccade into the next fixation); blinks
    every few seconds."""
    grid = np.arange(0.0, t_end_s + dt_s, dt_s)
    xy = np.empty((grid.size, 2))
    starts = np.array([f.t0_s for f in fixations])
    idx = np.clip(np.searchsorted(starts, grid, side="right") - 1, 0, len(fixations) - 1)
    fx = np.array([[f.x, f.y] for f in fixations])
    xy[:] = fx[idx]
    for k, (s0, sd) in enumerate(saccades):
        if k + 1 >= len(fixations):
            break
        sel = (grid >= s0) & (grid < s0 + sd)
        tau = (grid[sel] - s0) / sd
        prof = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
        xy[sel] = fx[k] + (fx[k + 1] - fx[k]) * prof[:, None]
    blinks = []
    tb = float(rng.uniform(1.0, 4.0))
    while tb < t_end_s:
        dur = float(rng.uniform(0.1, 0.3))
        blinks.append((tb, tb + dur))
        tb += dur + float(rng.uniform(2.0, 6.0))
    return Scanpath(fixations, np.array(blinks).reshape(-1, 2), grid, xy)


@dataclass(frozen=True)
class TrackerModel:
    """Eye-tracker error model (angles in radians, times in µs)."""

    bias_rad: tuple[float, float]  # constant yaw, pitch error over the session
    slow_sd_rad: float  # slowly varying error
    fast_sd_rad: float  # per-row noise
    latency_us: float  # rows describe the eye this long before their timestamp
    depth_sd: float  # relative depth error
    rate_hz: float = 60.0
    missing_p: float = 0.02

    @staticmethod
    def random(rng: np.random.Generator) -> TrackerModel:
        return TrackerModel(
            bias_rad=tuple(np.radians(rng.normal(0.0, 0.9, 2))),
            slow_sd_rad=math.radians(rng.uniform(0.3, 0.7)),
            fast_sd_rad=math.radians(rng.uniform(0.2, 0.5)),
            latency_us=float(rng.uniform(5_000, 20_000)),
            depth_sd=float(rng.uniform(0.03, 0.12)),
        )


def row_times_us(t0_us: int, duration_s: float, rate_hz: float, missing_p: float, rng: np.random.Generator) -> np.ndarray:
    """Eye-tracking frame times: nominal rate with jitter, some rows missing."""
    period = 1e6 / rate_hz
    n = int(duration_s * rate_hz) + 1
    t = t0_us + np.arange(n) * period + rng.normal(0.0, period * 0.03, n)
    t = np.round(np.sort(t)).astype(np.int64)
    keep = rng.random(n) >= missing_p
    keep[0] = True
    return t[keep]


def gaze_angles(points_cpf: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(left_yaw, right_yaw, pitch, depth_m) as an Aria Gen1 vergence row reports a gaze point.

    Combined yaw = atan(x/z), pitch = atan(y/z); the per-eye yaws average (in tangent) to the
    combined yaw and differ by the vergence: left > right for a near target, as the README says.
    """
    p = np.asarray(points_cpf, dtype=np.float64).reshape(-1, 3)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    left = np.arctan((x + EYE_OFFSET_M) / z)
    right = np.arctan((x - EYE_OFFSET_M) / z)
    pitch = np.arctan(y / z)
    depth = np.linalg.norm(p, axis=1)
    return left, right, pitch, depth


def points_from_angles(yaw: np.ndarray, pitch: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """CPF points at ``depth`` along (tan yaw, tan pitch, 1)."""
    d = np.stack([np.tan(yaw), np.tan(pitch), np.ones_like(yaw)], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True) * np.asarray(depth)[:, None]


def tracker_rows(
    true_points_cpf: np.ndarray, t_rows_us: np.ndarray, blink: np.ndarray, model: TrackerModel, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Noisy (left_yaw, right_yaw, pitch, depth_m) rows for the true gaze points of each row."""
    p = np.asarray(true_points_cpf, dtype=np.float64)
    n = p.shape[0]
    yaw = np.arctan(p[:, 0] / p[:, 2])
    pitch = np.arctan(p[:, 1] / p[:, 2])
    depth = np.linalg.norm(p, axis=1)
    # slow error: a random walk low-passed over ~1 s
    t_s = (t_rows_us - t_rows_us[0]) * 1e-6
    slow = np.zeros((n, 2))
    if n > 1:
        steps = rng.normal(0.0, 1.0, (n, 2))
        alpha = np.exp(-np.diff(t_s, prepend=t_s[0]) / 1.0)[:, None]
        for i in range(1, n):  # one short loop over rows (~60 per second), not per event
            slow[i] = alpha[i] * slow[i - 1] + np.sqrt(1 - alpha[i] ** 2) * steps[i]
    err = np.asarray(model.bias_rad)[None, :] + slow * model.slow_sd_rad + rng.normal(0.0, model.fast_sd_rad, (n, 2))
    yaw = yaw + err[:, 0]
    pitch = pitch + err[:, 1]
    depth = np.minimum(depth * (1.0 + rng.normal(0.0, model.depth_sd, n)), 4.0)
    if blink.any():  # eyelid closing: the tracker reports far-off gaze
        k = int(blink.sum())
        yaw[blink] += rng.normal(0.0, 0.3, k)
        pitch[blink] -= rng.uniform(0.2, 0.6, k)
        depth[blink] = rng.uniform(0.2, 4.0, k)
    noisy = points_from_angles(yaw, pitch, depth)
    left, right, pitch_out, depth_out = gaze_angles(noisy)
    return left, right, pitch_out, depth_out

"""Project Aria MPS eye-gaze CSVs, every published schema, read by column name.

Column order differs even between files of one schema, so columns are found by name. Angles are
converted at ingest to one convention, the *projection* convention of Gen1 (yaw = atan(x/z),
pitch = atan(y/z), direction proportional to (tan yaw, tan pitch, 1)); Gen2 writes its combined
pitch as an elevation angle asin(y/|v|) and its per-eye rays in spherical angles.

Schemas (``GazeTrack.schema``):

* ``gen1_v1``: ``yaw_rads_cpf, pitch_rads_cpf, depth_m`` + low/high bounds.
* ``gen1_v2``: the same + ``session_uid``.
* ``gen1_vergence``: per-eye ``left_yaw_rads_cpf, right_yaw_rads_cpf``, common pitch, ``depth_m``,
  per-angle bounds, eye origins, ``session_uid``. Combined yaw = atan((tan l + tan r) / 2). This is
  also the schema of darkread recordings (``write_gaze_csv``).
* ``gen2``: combined yaw / elevation, per-eye spherical yaw / pitch, eye origins; no depth or
  bounds. The depth is recovered from the two eye rays where they verge (as projectaria_tools
  does for its spatial gaze point).

A row is *valid* when its angles are finite and no confidence interval (high - low) is wider than
``max_bounds_width_rad``: Gen1 MPS does not flag blinks, but rows during a blink or a tracking
failure come with very wide intervals (up to ~1.3 rad in Meta's sample, against a median of
~0.05 rad). Zero-width intervals (the combined bounds of the vergence schema) mean "not given".
"""

from __future__ import annotations

import csv
import math
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darkread.edge.errors import GazeCsvError

MAX_BOUNDS_WIDTH_RAD = 0.5
"""Default widest confidence interval of a usable row (~29 degrees); wider means blink / failure."""

TIMESTAMP = "tracking_timestamp_us"

VERGENCE_COLUMNS: tuple[str, ...] = (
    TIMESTAMP,
    "left_yaw_rads_cpf",
    "right_yaw_rads_cpf",
    "pitch_rads_cpf",
    "depth_m",
    "left_yaw_low_rads_cpf",
    "right_yaw_low_rads_cpf",
    "pitch_low_rads_cpf",
    "left_yaw_high_rads_cpf",
    "right_yaw_high_rads_cpf",
    "pitch_high_rads_cpf",
    "tx_left_eye_cpf",
    "ty_left_eye_cpf",
    "tz_left_eye_cpf",
    "tx_right_eye_cpf",
    "ty_right_eye_cpf",
    "tz_right_eye_cpf",
    "session_uid",
)
"""The recording format's gaze columns, in its order (Gen1 vergence schema)."""

GEN1_EYE_OFFSET_M = 0.0315
# Gen2 spatial-gaze-point validity, as in projectaria_tools >= 2.2.
GEN2_MIN_VERGENCE_RAD = math.radians(0.75)
GEN2_MAX_MISS_M = 0.03
GEN2_MAX_DEPTH_M = 6.0

_REQUIRED: dict[str, tuple[str, ...]] = {
    "gen1_v1": (TIMESTAMP, "yaw_rads_cpf", "pitch_rads_cpf"),
    "gen1_v2": (TIMESTAMP, "yaw_rads_cpf", "pitch_rads_cpf", "session_uid"),
    "gen1_vergence": (TIMESTAMP, "left_yaw_rads_cpf", "right_yaw_rads_cpf", "pitch_rads_cpf", "depth_m"),
    "gen2": (
        TIMESTAMP,
        "yaw_rads_cpf",
        "pitch_rads_cpf",
        "left_yaw_rads_cpf",
        "right_yaw_rads_cpf",
        "left_pitch_rads_cpf",
        "right_pitch_rads_cpf",
        "tx_left_eye_cpf",
        "ty_left_eye_cpf",
        "tz_left_eye_cpf",
        "tx_right_eye_cpf",
        "ty_right_eye_cpf",
        "tz_right_eye_cpf",
    ),
}
_BOUND_ANGLES = ("yaw", "pitch", "left_yaw", "right_yaw")


@dataclass(frozen=True, eq=False)
class GazeTrack:
    """Gaze samples on the Aria device clock, sorted by time, angles in the projection convention."""

    t_us: np.ndarray
    yaw_rad: np.ndarray
    pitch_rad: np.ndarray
    depth_m: np.ndarray
    valid: np.ndarray
    schema: str
    session_uid: str | None
    bounds_width_rad: np.ndarray | None = None
    """Widest confidence interval per row (NaN where the schema has none)."""

    def __len__(self) -> int:
        return int(self.t_us.shape[0])

    def directions_cpf(self) -> np.ndarray:
        """Unit gaze directions in CPF (X left, Y up, Z forward), shape (N, 3)."""
        return projection_directions(self.yaw_rad, self.pitch_rad)

    @property
    def valid_fraction(self) -> float:
        return float(self.valid.mean()) if len(self) else 0.0


def projection_directions(yaw_rad: np.ndarray, pitch_rad: np.ndarray) -> np.ndarray:
    """Unit vectors along (tan yaw, tan pitch, 1)."""
    v = np.stack([np.tan(yaw_rad), np.tan(pitch_rad), np.ones(np.shape(yaw_rad))], axis=-1)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def elevation_to_projection_pitch(yaw_rad: np.ndarray, elevation_rad: np.ndarray) -> np.ndarray:
    """Pitch atan(y/z) of the direction with yaw atan(x/z) and elevation asin(y/|v|).

    Yaw is the same angle in both conventions; only pitch differs: tan(pitch) = tan(el) / cos(yaw).
    """
    return np.arctan(np.tan(elevation_rad) / np.cos(yaw_rad))


def spherical_directions(yaw_rad: np.ndarray, pitch_rad: np.ndarray) -> np.ndarray:
    """Gen2 per-eye rays: (sin yaw cos pitch, sin pitch, cos yaw cos pitch)."""
    cp = np.cos(pitch_rad)
    return np.stack([np.sin(yaw_rad) * cp, np.sin(pitch_rad), np.cos(yaw_rad) * cp], axis=-1)


def verged_depth_m(
    left_origin: np.ndarray, left_dir: np.ndarray, right_origin: np.ndarray, right_dir: np.ndarray
) -> np.ndarray:
    """Distance from the CPF origin to where two eye rays come closest; NaN where they don't verge.

    Invalid (NaN) when the vergence angle is below 0.75 degrees, the rays miss each other by more than
    3 cm, the point lies behind either eye or farther than 6 m (projectaria_tools' rules).
    """
    w0 = left_origin - right_origin
    a = np.einsum("ij,ij->i", left_dir, left_dir)
    b = np.einsum("ij,ij->i", left_dir, right_dir)
    c = np.einsum("ij,ij->i", right_dir, right_dir)
    d = np.einsum("ij,ij->i", left_dir, w0)
    e = np.einsum("ij,ij->i", right_dir, w0)
    denom = a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (b * e - c * d) / denom
        u = (a * e - b * d) / denom
        p_left = left_origin + s[:, None] * left_dir
        p_right = right_origin + u[:, None] * right_dir
        miss = np.linalg.norm(p_left - p_right, axis=1)
        cos_vergence = b / np.sqrt(a * c)
    vergence = np.arccos(np.clip(cos_vergence, -1.0, 1.0))
    depth = np.linalg.norm((p_left + p_right) / 2, axis=1)
    ok = (vergence >= GEN2_MIN_VERGENCE_RAD) & (miss <= GEN2_MAX_MISS_M) & (s > 0) & (u > 0)
    ok &= depth <= GEN2_MAX_DEPTH_M
    return np.where(ok, depth, np.nan)


def detect_schema(columns: list[str]) -> str:
    names = set(columns)
    if "left_pitch_rads_cpf" in names:
        return "gen2"
    if "left_yaw_rads_cpf" in names:
        return "gen1_vergence"
    if "session_uid" in names:
        return "gen1_v2"
    return "gen1_v1"


class _Table:
    """Numeric columns of a CSV, parsed with file/line-precise errors."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            with open(path, newline="", encoding="utf-8") as handle:
                rows = list(csv.reader(handle))
        except (OSError, UnicodeDecodeError) as exc:
            raise GazeCsvError(f"{path}: cannot read eye-gaze CSV: {exc}") from exc
        if not rows or not any(cell.strip() for cell in rows[0]):
            raise GazeCsvError(f"{path}, line 1: empty file, expected a header row starting with {TIMESTAMP}")
        self.header = [cell.strip() for cell in rows[0]]
        self.index = {name: i for i, name in enumerate(self.header)}
        # (line number, cells), blank lines skipped; line numbers count the header as line 1.
        self.rows = [(n + 2, row) for n, row in enumerate(rows[1:]) if any(cell.strip() for cell in row)]
        for line, row in self.rows:
            if len(row) != len(self.header):
                raise GazeCsvError(f"{path}, line {line}: {len(row)} cells, the header has {len(self.header)}")

    def require(self, names: tuple[str, ...], schema: str) -> None:
        missing = [name for name in names if name not in self.index]
        if missing:
            raise GazeCsvError(f"{self.path}, line 1: missing column(s) {', '.join(missing)} ({schema} schema)")

    def has(self, name: str) -> bool:
        return name in self.index

    def _cells(self, name: str) -> list[str]:
        col = self.index[name]
        return [row[col].strip() for _, row in self.rows]

    def floats(self, name: str, *, empty: float = math.nan) -> np.ndarray:
        cells = self._cells(name)
        try:  # fast path; the loop below finds the offending line
            values = np.array([cell or "nan" for cell in cells], dtype=np.float64)
            if not math.isnan(empty):
                values[[not cell for cell in cells]] = empty
            return values
        except ValueError:
            pass
        col = self.index[name]
        out = np.empty(len(self.rows))
        for i, (line, row) in enumerate(self.rows):
            cell = row[col].strip()
            if not cell:
                out[i] = empty
                continue
            try:
                out[i] = float(cell)
            except ValueError:
                raise GazeCsvError(f"{self.path}, line {line}: column {name}: {cell!r} is not a number") from None
        return out

    def integers(self, name: str) -> np.ndarray:
        try:
            return np.array(self._cells(name), dtype=np.int64)
        except (ValueError, OverflowError):
            pass
        col = self.index[name]
        out = np.empty(len(self.rows), dtype=np.int64)
        for i, (line, row) in enumerate(self.rows):
            cell = row[col].strip()
            try:
                out[i] = int(cell)
            except OverflowError:
                raise GazeCsvError(
                    f"{self.path}, line {line}: column {name}: {cell[:24]!r}... is beyond the 64-bit timestamp range"
                ) from None
            except ValueError:
                try:
                    value = float(cell)
                except ValueError:
                    value = math.nan
                if not value.is_integer() or abs(value) >= 2**63:
                    raise GazeCsvError(
                        f"{self.path}, line {line}: column {name}: {cell!r} is not an integer timestamp"
                    ) from None
                out[i] = int(value)
        return out

    def text(self, name: str) -> str | None:
        if name not in self.index or not self.rows:
            return None
        value = self.rows[0][1][self.index[name]].strip()
        return value or None


def read_gaze_csv(path: str | Path, *, max_bounds_width_rad: float = MAX_BOUNDS_WIDTH_RAD) -> GazeTrack:
    """Read an MPS eye-gaze CSV of any schema; ``GazeCsvError`` names the file and line on bad input."""
    path = Path(path)
    table = _Table(path)
    schema = detect_schema(table.header)
    table.require(_REQUIRED[schema], schema)
    t_us = table.integers(TIMESTAMP)
    pitch = table.floats("pitch_rads_cpf")
    depth = table.floats("depth_m") if table.has("depth_m") else np.full(len(t_us), np.nan)
    depth = np.where(depth > 0, depth, np.nan)  # empty or 0 = not available

    if schema == "gen1_vergence":
        tan_left, tan_right = np.tan(table.floats("left_yaw_rads_cpf")), np.tan(table.floats("right_yaw_rads_cpf"))
        yaw = np.arctan((tan_left + tan_right) / 2)
    elif schema == "gen2":
        yaw = table.floats("yaw_rads_cpf")
        depth = _gen2_depth(table)
        pitch = elevation_to_projection_pitch(yaw, pitch)
    else:
        yaw = table.floats("yaw_rads_cpf")

    width = _bounds_width(table)
    valid = np.isfinite(yaw) & np.isfinite(pitch) & ~(width > max_bounds_width_rad)
    order = np.argsort(t_us, kind="stable")
    return GazeTrack(
        t_us=t_us[order],
        yaw_rad=yaw[order],
        pitch_rad=pitch[order],
        depth_m=depth[order].astype(np.float64),
        valid=valid[order],
        schema=schema,
        session_uid=table.text("session_uid"),
        bounds_width_rad=width[order],
    )


def _gen2_depth(table: _Table) -> np.ndarray:
    def origin(eye: str) -> np.ndarray:
        return np.stack([table.floats(f"t{axis}_{eye}_eye_cpf") for axis in "xyz"], axis=1)

    left_dir = spherical_directions(table.floats("left_yaw_rads_cpf"), table.floats("left_pitch_rads_cpf"))
    right_dir = spherical_directions(table.floats("right_yaw_rads_cpf"), table.floats("right_pitch_rads_cpf"))
    return verged_depth_m(origin("left"), left_dir, origin("right"), right_dir)


def _bounds_width(table: _Table) -> np.ndarray:
    widths = []
    for angle in _BOUND_ANGLES:
        low, high = f"{angle}_low_rads_cpf", f"{angle}_high_rads_cpf"
        if table.has(low) and table.has(high):
            widths.append(np.abs(table.floats(high) - table.floats(low)))
    if not widths:
        return np.full(len(table.rows), np.nan)
    return np.fmax.reduce(np.stack(widths), axis=0)  # NaN only where no bound is given


def write_gaze_csv(
    path: str | Path,
    t_us: np.ndarray,
    left_yaw_rad: np.ndarray,
    right_yaw_rad: np.ndarray,
    pitch_rad: np.ndarray,
    depth_m: np.ndarray,
    *,
    bounds_rad: float = 0.05,
    session_uid: str | None = None,
) -> None:
    """Write the recording format's gaze CSV (Gen1 vergence schema, columns in the format's order).

    Bounds are written symmetric, ``value +- bounds_rad``; a NaN or non-positive depth is written as
    an empty cell ("not available"); eye origins are the Gen1 +-0.0315 m.
    """
    t_us = np.asarray(t_us, dtype=np.int64)
    columns = [np.asarray(a, dtype=np.float64) for a in (left_yaw_rad, right_yaw_rad, pitch_rad, depth_m)]
    n = t_us.shape[0]
    if any(c.shape != (n,) for c in columns):
        raise ValueError(f"write_gaze_csv: all columns must have shape ({n},)")
    uid = session_uid or str(uuid.uuid4())
    left, right, pitch, depth = columns
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(VERGENCE_COLUMNS)
        for i in range(n):
            angles = (left[i], right[i], pitch[i])
            d = depth[i]
            writer.writerow(
                [
                    int(t_us[i]),
                    *(repr(float(a)) for a in angles),
                    repr(float(d)) if np.isfinite(d) and d > 0 else "",
                    *(repr(float(a - bounds_rad)) for a in angles),
                    *(repr(float(a + bounds_rad)) for a in angles),
                    repr(GEN1_EYE_OFFSET_M), "0.0", "0.0",
                    repr(-GEN1_EYE_OFFSET_M), "0.0", "0.0",
                    uid,
                ]
            )

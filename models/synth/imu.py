"""The glasses' gyroscope for a synthetic recording: the simulator's head rotation through a MEMS model.

The head's rotation is the simulator's own (``Scene.pose``: the world turns by ``R_head(t)`` in the
camera frame, so the camera turns by its inverse); its angular velocity is taken from ``R_head`` a
millisecond apart and rotated into the device frame, which in the recording format is the CPF
(``T_event_cpf``'s rotation maps CPF vectors into the event camera: ``w_event = R w_cpf``). The
page's own motion and the head's translation are not rotation of the head: a gyroscope does not see
them.

The MEMS model (``MemsGyro``; figures in docs/head_motion.md with the datasheets they come from),
applied in the chip's own axes and rotated into the device frame as the chip is mounted (Aria's
left IMU, ``T_Device_Imu`` of projectaria_tools' sample calibration):

* white rate noise of ``noise_density`` (deg/s/sqrt(Hz)); per sample its sd is density * sqrt(rate),
* a turn-on bias per axis (what a factory calibration leaves), drifting as a random walk,
* a scale error per axis, and 16-bit quantisation of a +-500 deg/s range,
* sample-time jitter: the samples are taken ``jitter_us`` (sd) around the nominal 1 kHz grid and
  stamped at the instant taken, as Aria's irregular 1 kHz stamps are.

Its randomness comes from its own generator (``write_recording`` seeds it apart), so adding the
stream changes no other file of a recording.
"""

from __future__ import annotations

import math
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darkread.edge.imu_motion import quaternions_xyzw, rotation_matrices, rotation_vectors
from darkread.edge.io.imu_csv import write_imu_csv
from darkread.models.synth.scene import Scene

# Aria Gen1's left IMU in its device frame (projectaria_tools, data/gen1/mps_sample/trajectory/
# online_calibration.jsonl, ImuCalibrations "imu-left" T_Device_Imu.UnitQuaternion: w, (x, y, z))
ARIA_IMU_LEFT_Q_WXYZ = (0.023948255122171, -0.701422965925179, -0.71141490939221, 0.036347360891833)


def quaternion_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    """The rotation matrix of a unit quaternion (Hamilton convention, as projectaria_tools / Sophus)."""
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


@dataclass(frozen=True)
class MemsGyro:
    """A consumer MEMS gyroscope (BMI270 / ICM-42688 class) sampled at ``rate_hz``."""

    rate_hz: float = 1000.0
    noise_density_deg_s_rthz: float = 0.007  # BMI270 datasheet: 0.007 dps/sqrt(Hz) (ICM-42688-P: 0.0028)
    bias_sd_deg_s: float = 0.3  # turn-on bias left after calibration (Aria's online calibration: 0.1-0.4 deg/s)
    bias_walk_deg_s_rts: float = 0.002  # rate random walk: the bias drifts by this sd per sqrt(second)
    scale_sd: float = 0.003  # scale error per axis (Aria's rectification matrices: 0.1-2 %)
    lsb_deg_s: float = 1000.0 / 65536  # 16-bit over +-500 deg/s
    jitter_us: float = 30.0  # sd of the sampling instants around the nominal grid
    R_device_imu: tuple[float, float, float, float] = ARIA_IMU_LEFT_Q_WXYZ

    def measure(self, t_s: np.ndarray, omega_device: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """What the chip reports (rad/s, device frame) at instants ``t_s`` [n] of true rates [n, 3]."""
        R = quaternion_matrix(*self.R_device_imu)
        chip = omega_device @ R  # device -> chip axes (R^T w, row by row)
        n = chip.shape[0]
        dt = np.diff(t_s, prepend=t_s[0])
        walk = np.cumsum(rng.normal(0.0, 1.0, (n, 3)) * np.sqrt(dt)[:, None], axis=0) * self.bias_walk_deg_s_rts
        bias = rng.normal(0.0, self.bias_sd_deg_s, 3) + walk
        noise = rng.normal(0.0, self.noise_density_deg_s_rthz * math.sqrt(self.rate_hz), (n, 3))
        scale = 1.0 + rng.normal(0.0, self.scale_sd, 3)
        reading = np.degrees(chip) * scale + bias + noise
        reading = np.round(reading / self.lsb_deg_s) * self.lsb_deg_s
        return np.radians(reading) @ R.T  # chip -> device


def head_rotation(scene: Scene, t_s: np.ndarray) -> np.ndarray:
    """[n, 3, 3]: ``R_head(t)``, how the world turns in the camera frame (``Scene.pose``)."""
    angles = np.stack([scene.motion.at(float(t))[0] for t in t_s])  # (1 kHz of sums of sinusoids: ~1 s per 10 s)
    return rotation_matrices(angles)


def true_rates_device(scene: Scene, t_s: np.ndarray, h_s: float = 2e-4) -> np.ndarray:
    """[n, 3]: the head's angular velocity (rad/s) in the device frame (CPF) at ``t_s``.

    The camera turns by ``R_head^T``; its body rate ``w`` satisfies ``R_head(t + h) R_head(t)^T =
    exp(-[w] h)`` (camera frame), then ``w_cpf = R_event_cpf^T w``."""
    before, after = head_rotation(scene, t_s - h_s / 2), head_rotation(scene, t_s + h_s / 2)
    w_camera = -rotation_vectors(after @ np.transpose(before, (0, 2, 1))) / h_s
    R_event_cpf = np.asarray(scene.calib.T_event_cpf)[:3, :3]
    return w_camera @ R_event_cpf


def write_imu(path: Path, scene: Scene, seconds: float, device_t0_us: int, rng: np.random.Generator,
              gyro: MemsGyro = MemsGyro()) -> dict:
    """Write ``closed_loop_trajectory.csv`` for a recording of ``seconds`` starting at ``device_t0_us``
    (device clock): MEMS-like angular velocity, the true orientation of the device (world: the CPF
    of the head at rest, y up, so gravity is -9.81 m/s^2 along its y). Returns what ``meta.json`` may say about it."""
    n = int(math.floor(seconds * gyro.rate_hz)) + 1
    nominal = np.arange(n) / gyro.rate_hz
    t_s = np.clip(nominal + rng.normal(0.0, gyro.jitter_us * 1e-6, n), 0.0, seconds)
    t_s = np.maximum.accumulate(t_s)
    t_us = device_t0_us + np.round(t_s * 1e6).astype(np.int64)
    keep = np.concatenate([[True], np.diff(t_us) > 0])
    t_us, t_s = t_us[keep], t_s[keep]
    measured = gyro.measure(t_s, true_rates_device(scene, t_s), rng)
    R_event_cpf = np.asarray(scene.calib.T_event_cpf)[:3, :3]
    R_world_device = R_event_cpf.T @ np.transpose(head_rotation(scene, t_s), (0, 2, 1)) @ R_event_cpf
    uid = str(uuid.UUID(bytes=rng.integers(0, 256, 16).astype(np.uint8).tobytes(), version=4))
    write_imu_csv(path, t_us, measured, quaternions_xyzw(R_world_device), graph_uid=uid,
                  utc_offset_ns=1_767_225_600_000_000_000, gravity_world=(0.0, -9.81, 0.0))  # (2026-01-01, the date the RAW header carries)
    return {"rate_hz": gyro.rate_hz, "noise_density_deg_s_rthz": gyro.noise_density_deg_s_rthz,
            "bias_sd_deg_s": gyro.bias_sd_deg_s, "bias_walk_deg_s_rts": gyro.bias_walk_deg_s_rts}

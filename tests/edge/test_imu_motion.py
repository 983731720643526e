"""The head's motion from the gyroscope: rotations, bias, integration against a known rotation,
gaps and the fallback to the event tracker, the deblur searched around the prediction."""

from __future__ import annotations

import numpy as np
import pytest
from factories import moving_strokes

from darkread.edge.deblur import DeblurConfig, deblur_window, smear_near, smear_of
from darkread.edge.head_motion import KnownHeadMotion, SmearPrior
from darkread.edge.imu_motion import (
    ImuHeadMotion,
    ImuMotionConfig,
    JoinedSceneMotion,
    Rows,
    integrate,
    rotation_matrices,
    rotation_vectors,
    running_bias,
    shift_px,
    shift_px_one,
    step_band_rms,
    still_samples,
)
from darkread.edge.io.calibration import Calibration
from darkread.edge.io.imu_csv import ImuTrack

FX = 1400.0
CPF_TO_CAMERA = np.diag([-1.0, -1.0, 1.0, 1.0])  # CPF x left, y up -> camera x right, y down


def calibration(offset_us: int = 0) -> Calibration:
    return Calibration(width=1280, height=720, fx=FX, fy=FX, cx=640.0, cy=360.0, distortion=(0.0, 0.0, 0.0, 0.0),
                       T_event_cpf=CPF_TO_CAMERA, gaze_to_event_time_offset_us=offset_us)


def steady_turn(rate_cpf: tuple[float, float, float], seconds: float = 1.0, bias=(0.0, 0.0, 0.0),
                still_s: float = 0.0, t0: int = 5_000_000) -> ImuTrack:
    """1 kHz samples: ``still_s`` of a still head, then a steady turn at ``rate_cpf`` rad/s; plus ``bias``."""
    t = t0 + np.arange(int((still_s + seconds) * 1000) + 1, dtype=np.int64) * 1000
    omega = np.where(((t - t0) * 1e-6 >= still_s)[:, None], np.asarray(rate_cpf), 0.0) + np.asarray(bias)
    return ImuTrack(t, omega)


def test_rotation_helpers_agree_with_each_other() -> None:
    rotvecs = np.random.default_rng(1).normal(0, 0.5, (20, 3))
    matrices = rotation_matrices(rotvecs)
    assert np.allclose(matrices @ np.transpose(matrices, (0, 2, 1)), np.eye(3), atol=1e-12)
    assert np.allclose(rotation_vectors(matrices), rotvecs, atol=1e-9)


def test_the_one_rotation_shift_is_the_vectorised_one_bit_for_bit() -> None:
    lens = Calibration(width=1280, height=720, fx=FX, fy=FX * 1.01, cx=631.5, cy=352.25, distortion=(-0.12, 0.05, 1e-3, -2e-3),
                       T_event_cpf=CPF_TO_CAMERA)
    rng = np.random.default_rng(7)
    for rotvec, centre in zip(rng.normal(0, 0.02, (50, 3)), rng.uniform((0, 0), (1280, 720), (50, 2))):
        expected = shift_px(lens, (float(centre[0]), float(centre[1])), rotvec[None])[0]
        assert shift_px_one(lens, (float(centre[0]), float(centre[1])), rotvec) == (float(expected[0]), float(expected[1]))
    assert shift_px_one(lens, (640.0, 360.0), np.zeros(3)) == pytest.approx((0.0, 0.0), abs=1e-9)  # (the undistortion's residue)


def test_a_steady_turn_moves_the_scene_by_the_homography() -> None:
    # the wearer turns left (about CPF +y, up) at 0.1 rad/s: the camera pans left, the page moves right
    rate = 0.1
    motion = ImuHeadMotion.of_track(steady_turn((0.0, rate, 0.0), seconds=1.0), calibration())
    assert isinstance(motion, KnownHeadMotion) and isinstance(motion, SmearPrior)
    t0, t1 = 5_600_000, 5_900_000  # (the first half second decides whether the head walks)
    a, b = motion.scene_px(t0), motion.scene_px(t1)
    assert a is not None and b is not None
    expected = FX * np.tan(rate * 0.3 + np.arctan(a[0] / FX)) - a[0]  # pure rotation about the optical centre
    assert b[0] - a[0] == pytest.approx(expected, rel=1e-3) and abs(b[1] - a[1]) < 1e-6
    # the deblur's smear over 20 ms: the same shift at the window's centre
    smear = motion.smear_prior(t1 - 20_000, t1, (640.0, 360.0))
    assert smear is not None and smear[0] == pytest.approx(FX * rate * 0.02, rel=0.02)


def test_the_device_clock_is_mapped_by_the_calibrations_offset() -> None:
    track = steady_turn((0.0, 0.1, 0.0), seconds=1.0)
    plain = ImuHeadMotion.of_track(track, calibration())
    shifted = ImuHeadMotion.of_track(track, calibration(offset_us=-3_000_000))
    assert shifted.scene_px(5_500_000 - 3_000_000) == plain.scene_px(5_500_000)


def test_the_bias_is_learnt_while_the_head_is_still() -> None:
    bias = (0.004, -0.006, 0.003)  # ~0.3 deg/s per axis, as a calibrated MEMS gyroscope leaves
    track = steady_turn((0.0, 0.0, 0.0), seconds=0.001, bias=bias, still_s=20.0)
    noisy = ImuTrack(track.t_us, track.omega + np.random.default_rng(2).normal(0, 0.004, track.omega.shape))
    still = still_samples(noisy.t_us, noisy.omega, ImuMotionConfig())
    assert still[100:].all()
    estimate = running_bias(noisy.t_us, noisy.omega, still, 10_000_000)
    assert np.allclose(estimate[-1], bias, atol=5e-4)
    # the edge's estimate is shrunk towards zero (``bias_prior_us``): 10 s of still samples against
    # 5 s of prior learn two thirds of it, a third of a calibrated bias's drift is left
    motion = ImuHeadMotion.of_track(noisy, calibration())
    a, b = motion.scene_px(23_000_000), motion.scene_px(25_000_000)
    uncorrected = FX * float(np.linalg.norm(bias)) * 2.0  # what the bias alone would drift in 2 s
    assert a is not None and b is not None and np.hypot(b[0] - a[0], b[1] - a[1]) < 0.4 * uncorrected


def test_a_slow_turn_is_not_taken_for_bias() -> None:
    """A head turning at 1 deg/s (under ``still_rad_s``: it passes as still) keeps most of its motion:
    with no prior the estimate took the whole turn for bias within 100 ms and the page stood still."""
    track = steady_turn((0.0, 0.0175, 0.0), seconds=3.0)
    seen = ImuHeadMotion.of_track(track, calibration())
    exact = ImuHeadMotion.of_track(track, calibration(), ImuMotionConfig(still_rad_s=0.0))  # no bias learnt
    a, b = seen.scene_px(5_500_000), seen.scene_px(8_000_000)
    a0, b0 = exact.scene_px(5_500_000), exact.scene_px(8_000_000)
    assert a is not None and b is not None and a0 is not None and b0 is not None
    moved, truly = np.hypot(b[0] - a[0], b[1] - a[1]), np.hypot(b0[0] - a0[0], b0[1] - a0[1])
    assert truly > 30.0 and moved > 0.6 * truly
    assert ImuHeadMotion.of_track(track, calibration(), ImuMotionConfig(bias_prior_us=0)).scene_px(8_000_000) is not None


def test_a_turning_head_is_not_taken_for_bias() -> None:
    t = np.arange(3001, dtype=np.int64) * 1000
    omega = np.c_[np.zeros(3001), np.full(3001, 0.3), np.zeros(3001)]
    assert not still_samples(t, omega).any()
    assert np.array_equal(running_bias(t, omega, still_samples(t, omega), 10_000_000), np.zeros((3001, 3)))


def test_integration_skips_gaps_and_gaps_are_not_healthy() -> None:
    t = np.concatenate([np.arange(0, 900_000, 1000), np.arange(1_000_000, 1_600_000, 1000)]).astype(np.int64)
    omega = np.tile([0.0, 0.2, 0.0], (t.shape[0], 1))
    theta = integrate(t, omega, gap_us=20_000)
    assert theta[-1, 1] == pytest.approx(0.2 * (0.899 + 0.599))  # nothing integrated across the 101-ms gap
    motion = ImuHeadMotion.of_track(ImuTrack(t, omega), calibration())
    assert motion.available and motion.healthy(700_000)
    assert not motion.healthy(50_000)  # the stream's first trust span
    assert not motion.healthy(300_000)  # too little yet to tell whether the head walks
    assert not motion.healthy(950_000)  # inside the gap
    assert not motion.healthy(1_050_000)  # just after it
    assert motion.healthy(1_150_000)
    assert not motion.healthy(1_700_000)  # after the file's end
    assert motion.scene_px(950_000) is None and motion.smear_prior(940_000, 960_000, (640.0, 360.0)) is None


def test_the_step_bands_rms_is_a_sines_amplitude_over_root_two() -> None:
    t = np.arange(0, 3_000_000, 1000, dtype=np.int64)
    ends = np.array([1_000_000, 2_000_000, 2_999_000], dtype=np.int64)
    for hz, inside in ((1.8, True), (0.3, False), (8.0, False)):  # the step rate; reading drift; tremor
        omega = np.zeros((t.shape[0], 3))
        omega[:, 0] = 0.1 * np.sin(2 * np.pi * hz * t * 1e-6) + 0.02 * t * 1e-6  # (and a slow trend)
        rms = step_band_rms(t, omega, ends)
        if inside:
            assert rms[1:] == pytest.approx(0.1 / np.sqrt(2), rel=0.1)
        else:
            assert (rms < 0.01).all()
    assert np.isnan(step_band_rms(t, omega, np.array([200_000], dtype=np.int64)))[0]  # too short to tell


def test_the_step_band_is_the_same_taken_a_few_blocks_at_a_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """A long track's spectra are taken in batches (one array of every block's 2-s span would take
    gigabytes for an hour of samples); the batches change nothing."""
    import darkread.edge.imu_motion as imu_motion

    rng = np.random.default_rng(4)
    t = np.arange(0, 6_000_000, 1000, dtype=np.int64)
    omega = rng.normal(0.0, 0.02, (t.shape[0], 3))
    ends = np.arange(100_000, 6_000_000, 100_000, dtype=np.int64)
    whole = step_band_rms(t, omega, ends)
    monkeypatch.setattr(imu_motion, "STEP_BLOCKS_AT_ONCE", 7)
    np.testing.assert_array_equal(step_band_rms(t, omega, ends), whole)
    assert np.isnan(whole[:4]).all() and np.isfinite(whole[4:]).all()  # (the first half second tells nothing)


def test_a_live_stream_a_datagram_at_a_time_is_the_file_read_at_once() -> None:
    """Each datagram's bias, integration and walking decision come from the sums held, not from the
    whole history again (which cost most of a core once a minute was held): the same track either way."""
    rng = np.random.default_rng(9)
    n = 12_000
    t = 5_000_000 + np.arange(n, dtype=np.int64) * 1000
    omega = rng.normal(0.0, 0.01, (n, 3)) + 0.004 + 0.05 * np.sin(2 * np.pi * 0.3 * np.arange(n) / 1000)[:, None]
    omega[6000:6100] += 0.4  # a quick turn
    at_once = ImuHeadMotion.of_track(ImuTrack(t, omega), calibration())
    live = ImuHeadMotion(calibration(), live=True)
    for k in range(0, n, 20):
        live.extend(t[k:k + 20], omega[k:k + 20])
    asked = np.linspace(t[0], t[-1], 5000)
    np.testing.assert_allclose(live.rotation_at(asked), at_once.rotation_at(asked), rtol=0, atol=1e-12)
    assert [live.healthy(int(x)) for x in asked[::25]] == [at_once.healthy(int(x)) for x in asked[::25]]
    assert live.walking(int(t[-1])) == at_once.walking(int(t[-1]))


def test_a_live_streams_history_is_trimmed_and_its_buffers_stay_bounded() -> None:
    cfg = ImuMotionConfig(keep_us=2_000_000)
    live = ImuHeadMotion(calibration(), cfg, live=True)
    t = 5_000_000 + np.arange(20_000, dtype=np.int64) * 1000
    for k in range(0, t.shape[0], 20):
        live.extend(t[k:k + 20], np.full((20, 3), 0.01))
    assert live.span_us is not None and live.span_us[1] - live.span_us[0] <= 2 * cfg.keep_us
    assert live._t_rows._buf.shape[0] <= 4 * 2 * 2_000 + 1024  # samples of keep_us at 1 kHz, grown by doubling
    assert live.healthy(int(t[-1])) and not live.healthy(int(t[0]))


def test_a_sample_that_is_not_a_number_is_dropped_not_summed_into_every_later_one() -> None:
    t = 5_000_000 + np.arange(3000, dtype=np.int64) * 1000
    omega = np.full((3000, 3), 0.01)
    omega[1000] = np.nan  # (a feed that does not check, e.g. a hardware callback)
    broken = ImuHeadMotion(calibration(), live=True)
    for k in range(0, 3000, 20):
        broken.extend(t[k:k + 20], omega[k:k + 20])
    clean = ImuHeadMotion(calibration(), live=True)
    clean.extend(np.delete(t, 1000), np.delete(omega, 1000, axis=0))
    asked = np.linspace(t[0], t[-1], 200)
    assert np.isfinite(broken.rotation_at(asked)).all()
    np.testing.assert_allclose(broken.rotation_at(asked), clean.rotation_at(asked), rtol=0, atol=1e-12)


def test_rows_grow_and_trim_from_the_front() -> None:
    rows = Rows(np.zeros((0, 2)))
    rows.append(np.ones((3, 2)))
    rows.drop_front(2)
    rows.append(np.arange(4.0).reshape(2, 2))
    np.testing.assert_array_equal(rows.view, [[1.0, 1.0], [0.0, 1.0], [2.0, 3.0]])


def test_a_walking_head_is_not_trusted_to_the_gyroscope() -> None:
    """Walking pitches the head at the step rate and bobs the page against it: the edge then takes the events' motion."""
    t = np.arange(0, 4_000_000, 1000, dtype=np.int64)
    seated = np.zeros((t.shape[0], 3))
    seated[:, 0] = np.radians(0.5) * 2 * np.pi * 0.3 * np.cos(2 * np.pi * 0.3 * t * 1e-6)  # slow reading drift, 0.5 deg
    walking = seated.copy()
    walking[2_000:, 0] += np.radians(0.5) * 2 * np.pi * 1.9 * np.cos(2 * np.pi * 1.9 * t[2_000:] * 1e-6)  # walks from 2 s
    quiet = ImuHeadMotion.of_track(ImuTrack(t, seated), calibration())
    walker = ImuHeadMotion.of_track(ImuTrack(t, walking), calibration())
    assert all(quiet.healthy(int(x)) for x in range(600_000, 4_000_000, 100_000))
    assert walker.healthy(1_500_000) and not walker.walking(1_500_000)
    assert walker.walking(3_000_000) and not walker.healthy(3_000_000) and walker.scene_px(3_000_000) is None


def test_the_tracker_takes_over_in_a_gap_and_the_track_stays_continuous() -> None:
    joined = JoinedSceneMotion()
    # both known from the start: the gyroscope continues the tracker's track (its origin is arbitrary) ...
    assert joined.at((0.0, 0.0), (100.0, 100.0)) == ((100.0, 100.0), None)
    # ... and the disagreement between frames is measured
    offset, disagreement = joined.at((5.0, 0.0), (104.0, 100.0))
    assert offset == (105.0, 100.0) and disagreement == pytest.approx(1.0)
    # a gap: the tracker continues from where the gyroscope was
    assert joined.at(None, (110.0, 100.0)) == ((111.0, 100.0), None)
    assert joined.at(None, (112.0, 101.0)) == ((113.0, 101.0), None)
    # the gyroscope back (its own origin far off): it continues the tracker's track
    assert joined.at((50.0, 50.0), (113.0, 101.0))[0] == (114.0, 101.0)
    assert joined.at((52.0, 50.0), (115.0, 101.0))[0] == (116.0, 101.0)
    # neither known: unknown
    assert joined.at(None, None) == (None, None)


def test_no_gyroscope_sample_at_all_leaves_the_tracker_as_it_is() -> None:
    joined = JoinedSceneMotion()
    assert joined.at(None, (3.0, 4.0)) == ((3.0, 4.0), None)
    assert joined.at(None, None) == (None, None)


def test_the_deblur_searches_around_the_prediction() -> None:
    velocity = (240.0, -120.0)  # px/s: a turning head
    events = moving_strokes(velocity, span_ms=30.0, seed=3)
    t_first, t_ref = int(events["t"][0]), int(events["t"][-1])
    span = float(t_ref - t_first)
    truth = (velocity[0] * span / 1e6, velocity[1] * span / 1e6)
    region = (480, 250, 320, 220)
    args = (events["x"], events["y"], events["t"], region, t_ref, span)
    found = smear_near(*args, (truth[0] + 1.2, truth[1] - 0.8), 2.0, DeblurConfig(), t_first_us=t_first)
    assert np.hypot(found[0] - truth[0], found[1] - truth[1]) < 0.6
    assert np.hypot(*np.subtract(found, smear_of(*args, DeblurConfig(), t_first_us=t_first))) < 0.6
    # too few events to sharpen: the prediction itself
    few = events[::400]
    assert smear_near(few["x"], few["y"], few["t"], region, t_ref, span, (3.0, 1.0), 2.0, DeblurConfig(),
                      t_first_us=t_first) == (3.0, 1.0)


@pytest.mark.parametrize("seed", range(3))
def test_a_prediction_the_events_do_not_beat_stands(seed) -> None:
    """Dim light (few events, half of them noise): around the gyroscope's prediction the search finds
    a peak a fraction above it, which is the noise's; unless the events sharpen by ``min_gain`` more
    there (the full search's test against a still page), the prediction stands."""
    events = moving_strokes((0.0, 0.0), span_ms=30.0, noise_share=0.5, seed=seed)[::6]
    t_first, t_ref = int(events["t"][0]), int(events["t"][-1])
    args = (events["x"], events["y"], events["t"], (480, 250, 320, 220), t_ref, float(t_ref - t_first))
    assert smear_near(*args, (0.5, 0.0), 2.0, DeblurConfig(), t_first_us=t_first) == (0.5, 0.0)
    assert smear_of(*args, DeblurConfig(), t_first_us=t_first) == (0.0, 0.0)


class _Prior:
    smear_radius_px = 2.0

    def __init__(self, smear: tuple[float, float] | None) -> None:
        self.smear = smear

    def smear_prior(self, t_first_us: int, t_ref_us: int, centre_px: tuple[float, float]) -> tuple[float, float] | None:
        return self.smear

    def healthy(self, t_us: int) -> bool:
        return self.smear is not None


def test_deblur_window_without_a_prediction_searches_as_before() -> None:
    events = moving_strokes((240.0, 0.0), span_ms=30.0, seed=4)
    origin, shape = (540, 310), (100, 200)
    inside = events[(events["x"] >= 540) & (events["x"] < 740) & (events["y"] >= 310) & (events["y"] < 410)]
    plain = deblur_window(inside, events, origin, shape, (1280, 720))
    unknown = deblur_window(inside, events, origin, shape, (1280, 720), prior=_Prior(None))
    assert plain[1] == unknown[1] and np.array_equal(plain[0], unknown[0])
    known = deblur_window(inside, events, origin, shape, (1280, 720), prior=_Prior(plain[1]))
    assert np.hypot(*np.subtract(known[1], plain[1])) < 0.6

"""``darkread calibrate intrinsics|clock|extrinsics|check|sensor``: make and check ``calibration.json``;
``sensor`` fits a sensor profile (the photoreceptor's K and the background-noise curve).

Order of a calibration session (see docs/calibration.md): intrinsics from a flashing board seen
from several angles; the clock from the board flashing while the glasses stay still (RGB frames
or the trigger input); the pose from the board seen by both cameras; then ``check`` on a reading
recording. Each step reads the calibration written by the one before (``--calibration``) and
writes an updated one (``--out``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
from pathlib import Path

logger = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "calibrate",
        help="make calibration.json (intrinsics, clock offset, pose) and check it",
        description=(
            "Calibrate the event camera on the glasses from captures of a flashing ArUco/ChArUco board: "
            "intrinsics, clock offset to the glasses' device clock, pose relative to the eyes' frame (CPF). "
            "`check` draws the gaze track over a recording's events to see whether a calibration is right."
        ),
    )
    sub = parser.add_subparsers(dest="calibrate_command", metavar="STEP")

    p = sub.add_parser("intrinsics", help="fx, fy, cx, cy and radtan distortion from a flashing or moved board",
                       description="Detect the board in every event burst of CAPTURE and run cv2.calibrateCamera.")
    p.add_argument("capture", help="capture directory (events.raw, board.json) or a .raw file")
    _common(p)
    p.add_argument("--tangential", action="store_true",
                   help="also fit p1, p2 (default 0: below detection noise for these lenses, and they trade off against cx, cy)")
    p.add_argument("--lamp", action="store_true",
                   help="a printed board moved between poses and lit by a lamp switched on at each (first-event latency images)")
    p.set_defaults(func=_intrinsics)

    p = sub.add_parser("clock", help="gaze_to_event_time_offset_us from flash times (RGB frames or trigger input)",
                       description=(
                           "Align the board's switches seen in the events (burst onsets, or edges on the external-trigger "
                           "input with --trigger) with the RGB frames' brightness (rgb_frames.csv, device clock). "
                           "Hold the glasses still. With --refine RECORDING, refine an offset on a reading recording by "
                           "cross-correlating event activity with gaze speed."
                       ))
    p.add_argument("capture", help="capture directory (events.raw, rgb_frames.csv) or, with --refine, a recording")
    _common(p)
    p.add_argument("--rgb-frames", help="rgb_frames.csv (default: CAPTURE/rgb_frames.csv)")
    p.add_argument("--trigger", action="store_true", help="take switch times from the external-trigger input")
    p.add_argument("--trigger-channel", type=int, default=None, help="trigger channel (default: all)")
    p.add_argument("--trigger-falling-shown", action="store_true", help="a falling edge means the board appeared")
    p.add_argument("--refine", action="store_true", help="CAPTURE is a reading recording: refine its offset")
    p.add_argument("--search-ms", type=float, default=40.0, help="refinement search range +- ms (default 40)")
    p.set_defaults(func=_clock)

    p = sub.add_parser("extrinsics", help="T_event_cpf from the board seen by the RGB and the event camera",
                       description=(
                           "solvePnP of the board in both cameras at the same instants, composed with the RGB camera's "
                           "pose relative to CPF. The RGB camera comes from --calibration's rgb_camera block (pinhole) or "
                           "from --aria-calibration (Fisheye624, with --T-device-cpf). --homography-only gives the flat-page "
                           "fallback for markers printed around a page, seen when a lamp is switched on (an RGB->event "
                           "homography, valid on that page only, no pose; calibration.json is left unchanged)."
                       ))
    p.add_argument("capture", help="capture directory (events.raw, board.json, rgb_frames.csv)")
    _common(p)
    p.add_argument("--rgb-frames", help="rgb_frames.csv (default: CAPTURE/rgb_frames.csv)")
    p.add_argument("--aria-calibration", help="Aria device-calibration JSON (camera-rgb, FisheyeRadTanThinPrism)")
    p.add_argument("--aria-label", default="camera-rgb", help="camera label in the device calibration")
    p.add_argument("--T-device-cpf", dest="t_device_cpf", help="JSON file for --aria-calibration: T_device_cpf as a 4x4 list (rows first) or "
                        "{Translation, UnitQuaternion: [w, [x, y, z]]} (projectaria_tools get_transform_device_cpf)")
    p.add_argument("--homography-only", action="store_true", help="flat-page fallback: RGB->event homography, no pose")
    p.set_defaults(func=_extrinsics)

    p = sub.add_parser("check", help="draw the projected gaze track over a recording's events",
                       description="Accumulate a recording's events and draw the gaze track projected with the calibration.")
    p.add_argument("recording", help="recording directory")
    p.add_argument("--calibration", help="calibration.json to check (default: the recording's)")
    p.add_argument("--png", default="calibration_check.png", help="output picture (default calibration_check.png)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=_check)

    p = sub.add_parser("sensor", help="fit K (photoreceptor speed) and the background-noise curve: a sensor profile",
                       description=(
                           "Fit the photoreceptor's K (Hz per chip-lux) from a bright edge swept across the view and the "
                           "background activity (Hz per pixel) from a still blank card at three or more light levels "
                           "measured with a lux meter; write a sensor profile (JSON) that `darkread eval make-suite "
                           "--sensor-profile` and training draw from. Recordings: FOLDER's sub-folders (events.raw + "
                           "meta.json with a sensor_calibration block) and/or RAW files with their lux (--card, --edge, "
                           "--dark). See docs/calibration.md, \"Sensor\"."
                       ))
    p.add_argument("folder", nargs="?", help="folder of calibration recordings (sub-folders with events.raw and meta.json)")
    p.add_argument("--card", action="append", default=[], metavar="FILE.raw@LUX",
                   help="a still blank card at LUX (the lux meter's reading at the card), repeatable")
    p.add_argument("--edge", action="append", default=[], metavar="FILE.raw@LUX",
                   help="a bright edge swept once across a dark field at LUX, repeatable")
    p.add_argument("--dark", action="append", default=[], metavar="FILE.raw", help="the lens capped: the dark floor")
    p.add_argument("--card-reflectance", type=float, default=0.8, help="the card's reflectance (default 0.8, white card)")
    p.add_argument("--edge-reflectance", type=float, nargs=2, default=(0.8, 0.05), metavar=("BRIGHT", "DARK"),
                   help="the edge's two reflectances (default 0.8 0.05: white card over black)")
    p.add_argument("--f-number", type=float, help="the lens's f-number (default: the recordings' meta.json, else 2.4)")
    p.add_argument("--bias", action="append", default=[], metavar="NAME=OFFSET",
                   help="the biases the recordings were made at (offsets from factory; default: meta.json's, else factory)")
    p.add_argument("--out", default="sensor_profile.json", help="the profile to write (default sensor_profile.json)")
    p.add_argument("--json", action="store_true", help="print the profile as JSON")
    p.set_defaults(func=_sensor)
    parser.set_defaults(func=lambda args: parser.print_help() or 2)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--board", help="board description JSON (default: CAPTURE/board.json)")
    p.add_argument("--calibration", help="calibration.json to start from (default: CAPTURE/calibration.json if present)")
    p.add_argument("--out", help="write the updated calibration.json here")
    p.add_argument("--json", action="store_true", help="print the result as JSON")


def _start_calibration(args: argparse.Namespace, width: int = 1280, height: int = 720):
    import numpy as np

    from darkread.edge.io.calibration import Calibration, load_calibration

    capture = Path(args.capture)
    path = Path(args.calibration) if args.calibration else (capture / "calibration.json" if capture.is_dir() else None)
    if path is not None and path.is_file():
        return load_calibration(path)
    if args.calibration:
        from darkread.edge.errors import CalibrationError

        raise CalibrationError(f"{args.calibration}: calibration file not found")
    logger.warning("no calibration to start from: nominal values (identity-like pose, zero clock offset)")
    return Calibration(width, height, 1400.0, 1400.0, width / 2, height / 2, (0.0, 0.0, 0.0, 0.0),
                       np.diag([-1.0, -1.0, 1.0, 1.0]), 0)


def _finish(args: argparse.Namespace, result: dict, calibration=None) -> int:
    if calibration is not None and args.out:
        from darkread.edge.io.calibration import save_calibration

        save_calibration(args.out, calibration)
        result["written"] = str(args.out)
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        for key, value in result.items():
            print(f"  {key:24s} {value}")
    return 0


def _progress(chunks, path: Path):
    """Event chunks with a progress bar (events) for recordings big enough to take a while."""
    if path.stat().st_size < (64 << 20):
        yield from chunks
        return
    from tqdm import tqdm

    with tqdm(desc=path.name, unit="ev", unit_scale=True, leave=False) as bar:
        for events in chunks:
            bar.update(events.shape[0])
            yield events


def _intrinsics(args: argparse.Namespace) -> int:
    from darkread.edge.calibrate.capture import board_of, read_capture_events
    from darkread.edge.calibrate.intrinsics import calibrate_intrinsics, detect_views

    data = read_capture_events(args.capture)
    spec = board_of(args.capture, args.board)
    views = detect_views(data.events, spec, data.width, data.height, lamp=args.lamp)
    result = calibrate_intrinsics([v.detection for v in views if v.detection is not None], data.width, data.height,
                                  zero_tangential=not args.tangential)
    calib = _start_calibration(args, data.width, data.height)
    calib = dataclasses.replace(calib, width=data.width, height=data.height, fx=result.fx, fy=result.fy, cx=result.cx,
                                cy=result.cy, distortion=result.distortion)
    out = {"bursts": len(views), **result.to_dict()}
    return _finish(args, out, calib)


def _clock(args: argparse.Namespace) -> int:
    if args.refine:
        return _clock_refine(args)
    from darkread.edge.calibrate.capture import RGB_FRAMES_NAME, read_capture_events
    from darkread.edge.calibrate.clock import (
        fit_offset,
        load_rgb_frames,
        switches_from_bursts,
        switches_from_triggers,
    )
    from darkread.edge.calibrate.event_image import find_bursts

    data = read_capture_events(args.capture)
    capture = Path(args.capture)
    frames = load_rgb_frames(args.rgb_frames or (capture if capture.is_dir() else capture.parent) / RGB_FRAMES_NAME)
    if args.trigger:
        switches, shown = switches_from_triggers(data.triggers, channel=args.trigger_channel,
                                                 rising_means_shown=not args.trigger_falling_shown)
        source = "trigger"
    else:
        switches, shown = switches_from_bursts(find_bursts(data.events))
        source = "bursts"
    result = fit_offset(switches, shown, frames, source=source)
    calib = dataclasses.replace(_start_calibration(args, data.width, data.height),
                                gaze_to_event_time_offset_us=round(result.offset_us))
    return _finish(args, result.to_dict(), calib)


def _clock_refine(args: argparse.Namespace) -> int:
    from darkread.edge.calibrate.check import gaze_track_pixels
    from darkread.edge.calibrate.clock import ActivityCounter, refine_offset
    from darkread.edge.io.recording import open_recording

    recording = open_recording(args.capture, calibration=args.calibration)
    calib = recording.calibration
    track = recording.gaze()
    t_event, pixels = gaze_track_pixels(calib, track)
    activity = ActivityCounter()
    for events in _progress(recording.reader(chunk_bytes=4 << 20), recording.raw_path):
        activity.add(events["t"])
    t_device = t_event - calib.gaze_to_event_time_offset_us
    result = refine_offset(activity, t_device, pixels, float(calib.gaze_to_event_time_offset_us),
                           search_us=args.search_ms * 1000.0)
    if result.peak_correlation < 0.3:
        logger.warning("weak agreement of gaze speed and event activity (r = %.2f): the refinement is unreliable "
                       "(record with some head motion)", result.peak_correlation)
    calib = dataclasses.replace(calib, gaze_to_event_time_offset_us=round(result.offset_us))
    return _finish(args, result.to_dict(), calib)


def _extrinsics(args: argparse.Namespace) -> int:
    import numpy as np

    from darkread.edge.calibrate.cameras import (
        Camera,
        aria_camera_from_device_calibration,
        matrix_from_list,
        pose_from_aria_json,
        rgb_camera_from_calibration,
    )
    from darkread.edge.calibrate.capture import (
        RGB_FRAMES_NAME,
        board_of,
        page_view,
        paired_views,
        read_capture_events,
    )
    from darkread.edge.calibrate.clock import load_rgb_frames
    from darkread.edge.calibrate.event_image import find_bursts
    from darkread.edge.calibrate.extrinsics import (
        extrinsics_from_views,
        page_homography,
    )
    from darkread.edge.errors import CalibrationError
    from darkread.edge.io.calibration import calibration_to_dict

    data = read_capture_events(args.capture)
    spec = board_of(args.capture, args.board)
    calib = _start_calibration(args, data.width, data.height)
    capture = Path(args.capture)
    frames = load_rgb_frames(args.rgb_frames or (capture if capture.is_dir() else capture.parent) / RGB_FRAMES_NAME, lazy=True)
    bursts = find_bursts(data.events)
    if args.homography_only:
        event_det, rgb_det = page_view(data.events, bursts, frames, calib.gaze_to_event_time_offset_us, spec,
                                       data.width, data.height)
        homography = page_homography(event_det, rgb_det)
        logger.warning("homography fallback: valid only for points on this page; calibration.json is not changed")
        return _finish(args, homography.to_dict())
    pairs = paired_views(data.events, bursts, frames, calib.gaze_to_event_time_offset_us, spec, data.width, data.height)
    if not pairs:
        raise CalibrationError("the board was not found in both cameras at the same time (run `calibrate clock` first?)")
    event_camera = calib.intrinsics()
    rgb_camera: Camera
    if args.aria_calibration:
        if not args.t_device_cpf:
            raise CalibrationError("--aria-calibration needs --T-device-cpf (the CPF pose in the device frame)")
        rgb_camera, T_device_rgb = aria_camera_from_device_calibration(args.aria_calibration, label=args.aria_label)
        doc = json.loads(Path(args.t_device_cpf).read_text(encoding="utf-8"))
        T_device_cpf = pose_from_aria_json(doc, args.t_device_cpf) if isinstance(doc, dict) else matrix_from_list(doc, "--T-device-cpf")
        T_rgb_cpf = np.linalg.inv(T_device_rgb) @ T_device_cpf
    else:
        rgb_camera, T_rgb_cpf = rgb_camera_from_calibration(calibration_to_dict(calib))
    result = extrinsics_from_views(pairs, event_camera, rgb_camera, T_rgb_cpf)
    calib = dataclasses.replace(calib, T_event_cpf=result.T_event_cpf)
    return _finish(args, result.to_dict(), calib)


def _check(args: argparse.Namespace) -> int:
    from darkread.edge.calibrate.check import render_check, write_check_png
    from darkread.edge.io.recording import open_recording

    recording = open_recording(args.recording, calibration=args.calibration)
    chunks = _progress(recording.reader(chunk_bytes=4 << 20), recording.raw_path)
    title = Path(args.calibration).name if args.calibration else "calibration.json"
    result = render_check(chunks, recording.calibration, recording.gaze(), title=title)
    write_check_png(args.png, result)
    out = {**result.to_dict(), "png": str(args.png)}
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        print(f"  gaze samples drawn       {result.n_gaze}")
        print(f"  gaze on text             {result.on_text_fraction:.0%}")
        print(f"  picture                  {args.png}")
    return 0


def _sensor(args: argparse.Namespace) -> int:
    from darkread.edge.calibrate.sensor import calibrate_sensor, recording_from_argument, recordings_in
    from darkread.edge.calibrate.sensor_profile import save_sensor_profile
    from darkread.edge.errors import CalibrationError
    from darkread.edge.sources.evk4.cli import parse_biases

    recordings = recordings_in(args.folder) if args.folder else []
    bright, dark = args.edge_reflectance
    for target, items, reflectance in (("card", args.card, args.card_reflectance), ("edge", args.edge, bright),
                                       ("dark", args.dark, args.card_reflectance)):
        recordings += [recording_from_argument(target, text, reflectance, dark) for text in items]
    if not recordings:
        raise CalibrationError("no calibration recordings: give a FOLDER or --card/--edge FILE.raw@LUX")
    for name, value in (("--card-reflectance", args.card_reflectance), ("--edge-reflectance", bright), ("--edge-reflectance", dark)):
        if not 0 < value <= 1:
            raise CalibrationError(f"{name} {value:g}: a reflectance lies in (0, 1]")
    result = calibrate_sensor(recordings, f_number=args.f_number, biases=parse_biases(args.bias) if args.bias else None)
    save_sensor_profile(args.out, result.profile)
    doc = result.profile.to_dict()
    if args.json:
        print(json.dumps({**doc, "written": str(args.out)}, indent=1))
        return 0
    pr = doc["photoreceptor"]
    print(f"  K                        {pr['k_hz_per_chip_lux']:.1f} Hz per chip-lux (+- {pr['k_relative_sd']:.0%}; "
          f"f_max {pr['f_max_hz']:g} Hz assumed)")
    for edge in pr["edges"]:
        print(f"    {edge['recording']:22s} {edge['lux']:g} lux: time constant {edge['time_constant_us']:.0f} us, "
              f"{edge['tail_events']} events")
    for point in doc["noise"]["points"]:
        print(f"  background {point['lux']:>6g} lux     {point['rate_hz']:.3f} Hz per pixel ({point['pixels']} pixels)")
    if doc["noise"]["dark_floor_hz"] is not None:
        print(f"  dark floor               {doc['noise']['dark_floor_hz']:.3f} Hz per pixel")
    print(f"  written                  {args.out}")
    return 0

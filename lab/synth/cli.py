"""``darkread synth recording`` and ``darkread synth dataset``: synthetic reading sessions."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

MOTIONS = ("still", "normal", "walking")
KINDS = ("letters", "words", "pangram", "paragraph")


def register(subparsers: argparse._SubParsersAction) -> None:
    from darkread.models.synth.motion import MOTION_REGIMES
    from darkread.models.synth.sensor import REGIMES

    synth = subparsers.add_parser(
        "synth",
        help="make synthetic reading recordings and training shards",
        description="Simulate a person reading a printed page with event-camera glasses: page, head "
        "motion, reading gaze, low-light event sensor.",
    )
    sub = synth.add_subparsers(dest="synth_command", metavar="SUBCOMMAND")
    synth.set_defaults(func=lambda args: (synth.print_help(), 2)[1])

    rec = sub.add_parser(
        "recording",
        help="write one recording (events.raw, general_eye_gaze.csv, calibration.json, text.txt, meta.json)",
        description="Write a synthetic reading session in the recording format to OUT.",
    )
    rec.add_argument("out", metavar="OUT", help="output folder (created)")
    rec.add_argument("--lux", type=float, default=100.0, help="illuminance at the page (5..1000; default 100)")
    rec.add_argument("--motion", choices=MOTIONS, default="normal", help="head / page motion level")
    rec.add_argument("--kind", choices=KINDS, default="paragraph", help="what is printed")
    rec.add_argument("--seconds", type=float, default=10.0,
                     help="duration of the recording (s); with --read-once the longest it may last")
    rec.add_argument("--read-once", action="store_true",
                     help="end the recording when the reader has read the last line (no re-reading)")
    rec.add_argument("--text-split", choices=("train", "val"), default="train",
                     help="val: texts never used for training (for evaluation)")
    rec.add_argument("--seed", type=int, default=0, help="random seed (same seed, same recording)")
    rec.add_argument("--font", default=None, help="font face, e.g. 'DejaVu Sans' (default: random training font)")
    rec.add_argument("--xheight", type=float, default=None, help="x-height in event pixels (5..16; default random)")
    rec.add_argument("--lines", type=int, default=None, help="number of printed lines (default 3..10)")
    rec.add_argument("--line-chars", type=int, default=None, help="characters per line (default 20..50)")
    rec.add_argument("--scanpath", choices=("model", "human"), default="model",
                     help="model: the reading model's eye movements; human: a real reader's fixations replayed on "
                          "this page line by line (durations, regressions, skips, sweep undershoot, vertical drift; "
                          "shipped: one reader of the oz data, MIT licence)")
    rec.add_argument("--scanpath-file", default=None, metavar="FILE.json",
                     help="with --scanpath human: another human scanpath (the form of "
                          "models/synth/data/human_scanpath_oz.json; see models/synth/human_scanpath.py)")
    rec.add_argument("--regime", choices=REGIMES, default="standard",
                     help="sensor regime: standard (what training saw), shifted (higher, more spread thresholds, a "
                          "faster photoreceptor in the dark, more shot noise, leak and hot pixels, and a font never used in training: "
                          "the stand-in for a real camera when adapting the model) or fast-photoreceptor (standard, but the "
                          "photoreceptor keeps up in the dark: ~1 ms at 5 lux instead of 4-50 ms) or grounded (light on the chip "
                          "through the lens, the photoreceptor and background activity of published IMX636 measurements: "
                          "docs/sensor_model.md)")
    rec.add_argument("--biases", default="factory", metavar="PROFILE",
                     help="the IMX636 bias profile the sensor runs with: factory (default) or dark (lower thresholds, "
                          "a stronger low-pass; edge/sources/evk4/bias_profiles.py); modelled in the grounded regime")
    rec.add_argument("--f-number", type=float, default=2.4,
                     help="the lens's f-number (default 2.4): the share of the page's light on the chip (grounded regime)")
    rec.add_argument("--motion-regime", choices=MOTION_REGIMES, default="standard",
                     help="the head motion's draws: standard (default, what training saw) or grounded (tremor and reading "
                          "motion from measurements, drawn across their bands); quiet, central, strong: every band at its "
                          "low end, centre or high end (docs/head_motion_model.md)")
    rec.add_argument("--full-view", action="store_true",
                     help="simulate every pixel of the sensor (the page, its edge and a textured desk around it) "
                          "instead of the region the gaze reaches plus noise: the stream a sensor ROI is measured on; "
                          "about ten times slower")
    rec.add_argument("--markers", action="store_true",
                     help="print the text with ArUco markers around it (as `darkread train target` lays it out) and write "
                          "page.layout.json (every recording carries the simulator's true page pose per millisecond, "
                          "pose_truth.npz, and a plain page its ink, page_ink.npz: for scoring only)")
    rec.add_argument("--simulator", choices=("darkread", "hesim"), default="darkread",
                     help="what turns the rendered scene into events: darkread (our sensor model, default) or hesim "
                          "(hesim-3d's H-ESIM with its Sony IMX636 preset, a second, independent simulator; the "
                          "page, motion, gaze, calibration and truth files stay the same; `make hesim` installs it)")
    rec.set_defaults(func=_recording)

    ds = sub.add_parser(
        "dataset",
        help="write training shards (voxel grid + ideal ink mask) for the reconstruction network",
        description="Write SAMPLES training pairs as compressed shards plus dataset.json. Deterministic "
        "for a seed whatever the number of workers; an interrupted run resumes (finished shards are kept).",
    )
    ds.add_argument("out", metavar="OUT", help="output folder (created)")
    ds.add_argument("--samples", type=int, default=90000, help="number of samples (default 90000)")
    ds.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    ds.add_argument("--seed", type=int, default=0, help="dataset seed")
    ds.add_argument("--split", choices=("train", "val"), default="train",
                    help="train: training fonts and texts; val: validation texts, all fonts incl. held-out")
    ds.add_argument("--held-out", action="store_true", help="only the held-out font families")
    ds.add_argument("--more-fonts", action="store_true",
                    help="a training set drawn from two more families too (Computer Modern Sans and Roman, "
                         "matplotlib's): more letter shapes than the three training families")
    ds.add_argument("--shard-size", type=int, default=250, help="samples per shard")
    ds.add_argument("--lux", type=float, nargs=2, metavar=("LOW", "HIGH"),
                    help="light at the page, log-uniform between LOW and HIGH lux (default: the training range, "
                         "4 1200; e.g. 4 40 for a low-light set to mix into training)")
    ds.add_argument("--target-time", choices=("end", "evidence"), default="end",
                    help="when each target shows the page: end (the window's newest event, default) or evidence "
                         "(the time, up to 60 ms earlier, its events match best: in the dark events trail the page)")
    ds.add_argument("--regime", choices=REGIMES, default="standard", help="the sensor regime (default standard)")
    ds.add_argument("--sensor-profile", metavar="PROFILE",
                    help="with --regime grounded: draw the sensor around this measured profile (`darkread calibrate sensor`)")
    ds.add_argument("--biases", nargs="+", default=["factory"], metavar="PROFILE",
                    help="with --regime grounded: the IMX636 bias profiles the pages are made under, each page one of them "
                         "(default factory; `--biases factory dark` for a network that reads under both profiles the glasses "
                         "switch between)")
    ds.add_argument("--motion-regime", choices=MOTION_REGIMES, default="standard",
                    help="the head motion's draws (default standard; grounded: from measurements, docs/head_motion_model.md)")
    ds.set_defaults(func=_dataset)

    ev = sub.add_parser(
        "sensor-evidence",
        help="plot the grounded sensor model against the published IMX636 measurements (docs/sensor_model.md)",
        description="Draw background activity vs lux beside the published EVK4 fits and latency vs chip lux beside "
        "NIST's points; with --fit, first fit the noise constants to the published background curve and print them.",
    )
    ev.add_argument("--out", default="docs/sensor_model.png", help="the figure (PNG; default docs/sensor_model.png)")
    ev.add_argument("--draws", type=int, default=12, help="sensors drawn over the band for the shaded area (default 12)")
    ev.add_argument("--fit", action="store_true", help="fit the noise constants first (a few minutes) and print them")
    ev.set_defaults(func=_sensor_evidence)

    sc = sub.add_parser(
        "sensor-calibration",
        help="simulated `calibrate sensor` recordings (blank card at several lux, a swept edge) at a known K",
        description="Write what an EVK4 owner records for `darkread calibrate sensor` (a still blank card at each --lux, "
        "the lens capped, a bright edge swept over a dark field), made by the grounded simulator at --k. With --check, "
        "calibrate them too and print the recovered K and noise curve beside the truth (docs/calibration.md).",
    )
    sc.add_argument("out", metavar="OUT", help="output folder (created; one sub-folder per recording)")
    sc.add_argument("--k", type=float, nargs="+", default=[130.0],
                    help="the photoreceptor's K, Hz per chip-lux (default 130; several with --check)")
    sc.add_argument("--lux", type=float, nargs="+", default=[1.0, 3.0, 10.0, 30.0], help="the card's light levels")
    sc.add_argument("--edge-lux", type=float, default=20.0, help="the edge's light (default 20 lux)")
    sc.add_argument("--seconds", type=float, default=3.0, help="each card recording's length (default 3 s)")
    sc.add_argument("--card-pixels", type=int, default=32, help="the card's crop, N x N pixels (default 32)")
    sc.add_argument("--biases", default="factory", metavar="PROFILE", help="bias profile (factory or dark)")
    sc.add_argument("--seed", type=int, default=0)
    sc.add_argument("--check", action="store_true", help="calibrate each K's recordings and compare with the truth")
    sc.set_defaults(func=_sensor_calibration)

    bt = sub.add_parser(
        "background-table",
        help="write the table the glasses estimate the light level from (background rate vs lux per bias profile)",
        description="Run the central grounded sensor under each bias profile on a still page at each lux and write "
        "background events per pixel and second as JSON (default: edge/sources/evk4/background_rates.json, shipped).",
    )
    bt.add_argument("--out", default="edge/sources/evk4/background_rates.json", help="the table (JSON)")
    bt.add_argument("--pixels", type=int, default=512, help="pixels per light level (default 512)")
    bt.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per level (default 10)")
    bt.set_defaults(func=_background_table)


def _sensor_calibration(args: argparse.Namespace) -> int:
    from darkread.lab.synth import sensor_calibration as sc

    if len(args.k) > 1 and not args.check:
        raise ValueError("several --k values are for --check (one recording set per K under OUT)")
    if min(args.k) <= 0 or min(args.lux) <= 0 or args.seconds <= 0 or args.card_pixels < 4:
        raise ValueError("--k, --lux and --seconds must be positive and --card-pixels at least 4")
    specs = [sc.CalibrationSpec(k_hz_per_chip_lux=k, card_lux=tuple(args.lux), edge_lux=args.edge_lux,
                                card_seconds=args.seconds, card_wh=(args.card_pixels, args.card_pixels),
                                bias_profile=args.biases, seed=args.seed) for k in args.k]
    if not args.check:
        for folder in sc.write_calibration_recordings(args.out, specs[0]):
            print(folder)
        return 0
    print(sc.check_table(sc.run_check(args.out, specs)))
    return 0


def _background_table(args: argparse.Namespace) -> int:
    from darkread.lab.synth.background_table import write_background_table

    if args.pixels < 1 or args.seconds <= 0:
        raise ValueError("--pixels and --seconds must be positive")
    print(write_background_table(args.out, pixels=args.pixels, seconds=args.seconds))
    return 0


def _sensor_evidence(args: argparse.Namespace) -> int:
    from darkread.lab.synth import sensor_evidence

    if args.draws < 1:
        raise ValueError(f"--draws {args.draws}: draw at least one sensor")
    if not args.out.lower().endswith(".png"):
        raise ValueError(f"--out {args.out}: the figure is written as PNG (name it *.png)")
    if args.fit:
        print("noise fit:", sensor_evidence.fit_noise())
    lux = [b.x for b in sensor_evidence.PUBLISHED_BACKGROUND]
    rates = sensor_evidence.model_background(sensor_evidence.central_params(), np.array(lux))
    for band, rate in zip(sensor_evidence.PUBLISHED_BACKGROUND, rates):
        inside = "inside" if band.lo <= rate <= band.hi else "OUTSIDE"
        print(f"{band.x:5g} lux: model {rate:.3f} Hz, published {band.lo:g}-{band.hi:g} ({inside})")
    print(sensor_evidence.evidence_figure(args.out, draws=args.draws))
    return 0


def _dataset(args: argparse.Namespace) -> int:
    from darkread.models.synth.session import LUX_RANGE
    from darkread.models.synth.shards import build_dataset

    manifest = build_dataset(
        args.out,
        args.samples,
        workers=args.workers,
        seed=args.seed,
        split=args.split,
        held_out=args.held_out,
        shard_size=args.shard_size,
        target_time=args.target_time,
        more_fonts=args.more_fonts,
        lux_range=(args.lux[0], args.lux[1]) if args.lux else LUX_RANGE,
        regime=args.regime,
        sensor_profile=args.sensor_profile,
        biases=tuple(args.biases),
        motion_regime=args.motion_regime,
    )
    print(f"{manifest['samples']} samples in {len(manifest['shards'])} shards -> {args.out} "
          f"({manifest['samples_per_s']} samples/s)")
    return 0


def _recording(args: argparse.Namespace) -> int:
    from darkread.lab.synth.simulators import simulator_for
    from darkread.models.synth.recording import RecordingSpec, write_recording

    spec = RecordingSpec(
        lux=args.lux,
        motion=args.motion,
        kind=args.kind,
        seconds=args.seconds,
        seed=args.seed,
        font=args.font,
        xheight_px=args.xheight,
        n_lines=args.lines,
        line_chars=args.line_chars,
        split=args.text_split,
        read_once=args.read_once,
        scanpath="human" if args.scanpath_file else args.scanpath,
        scanpath_file=args.scanpath_file,
        regime=args.regime,
        markers=args.markers,
        simulator=args.simulator,
        f_number=args.f_number,
        bias_profile=args.biases,
        motion_regime=args.motion_regime,
        full_view=args.full_view,
    )
    if args.scanpath_file and not Path(args.scanpath_file).is_file():
        raise FileNotFoundError(f"--scanpath-file {args.scanpath_file}: no such file")
    meta = write_recording(args.out, spec, simulator=simulator_for(args.simulator))
    print(f"{args.out}: {meta['event_count']} events over {meta['duration_s']} s ({meta['event_rate_hz']:.0f} ev/s)")
    return 0

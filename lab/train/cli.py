"""``darkread train ...``: fit, export, evaluate, fine-tune and reproduce the shipped network.

Light module: torch and the training code are imported inside the handlers.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from darkread.models import FIGURE_PATH, MODELS_DIR

DEFAULT_TRAIN = Path("runs/data/train")  # relative to the working directory (`make train` runs at the repo root)
DEFAULT_VAL = Path("runs/data/val")



def _fit_config(args: argparse.Namespace):  # -> FitConfig
    from darkread.models.train.fit import FitConfig

    return FitConfig(
        batch_size=args.batch_size, lr=args.lr, time_budget_s=args.minutes * 60, max_epochs=args.epochs,
        threads=args.threads, seed=args.seed, crop=tuple(args.crop) if args.crop[0] > 0 else None,
        net=_net_config(args).to_dict(),
        teacher=str(args.teacher) if getattr(args, "teacher", None) else None,
    )


def _init_config(args: argparse.Namespace):  # -> NetConfig | None
    """The shape of the --init network (fine-tuning keeps it), if there is one."""
    init = getattr(args, "init", None)
    if init is None or not Path(init).is_file():
        return None
    from darkread.models.train.fit import is_exported_network, load_model

    if is_exported_network(init):
        from darkread.models.train.onnx_weights import onnx_config

        return onnx_config(init)
    return load_model(init).config


def _net_config(args: argparse.Namespace):  # -> NetConfig
    """--head, --widths and --blocks, each else the --init network's, else the default."""
    from darkread.models.train.net import NetConfig

    base = _init_config(args) or NetConfig()
    head = getattr(args, "head", None) or base.head
    widths = tuple(getattr(args, "widths", None) or base.widths)
    blocks = tuple(getattr(args, "blocks", None) or base.blocks)
    return NetConfig(widths=widths, blocks=blocks, head=head)


def _add_fit_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--run-dir", type=Path, default=Path("runs/binary_unet"), help="checkpoints and history (default runs/binary_unet)")
    p.add_argument("--minutes", type=float, default=45.0, help="wall-time budget for training (default 45)")
    p.add_argument("--epochs", type=int, default=30, help="at most this many epochs (default 30)")
    p.add_argument("--batch-size", type=int, default=32)
    p.add_argument("--lr", type=float, default=3e-3, help="peak learning rate (AdamW, cosine decay)")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads (default 2)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--crop", type=int, nargs=2, default=[64, 128], metavar=("H", "W"),
                   help="train on random HxW crops (default 64 128; 0 0 = whole windows)")
    p.add_argument("--head", choices=("full", "shuffle"), default=None,
                   help="the network's last stage: shuffle (at half resolution, 2x2 sub-pixel logits by a pixel "
                        "shuffle) or full (at full resolution: a third more time a window); default: the --init "
                        "network's, else shuffle")
    p.add_argument("--widths", type=_positive_int, nargs=4, default=None, metavar=("FULL", "HALF", "QUARTER", "EIGHTH"),
                   help="channels at the four scales (default: the --init network's, else the shipped one's, 8 16 32 96)")
    p.add_argument("--blocks", type=_positive_int, nargs=3, default=None, metavar=("HALF", "QUARTER", "EIGHTH"),
                   help="separable blocks at the three encoder scales (default: the --init network's, else the shipped one's, 1 2 8); "
                        "blocks at 1/8 scale widen the view at little cost a window")


def _cmd_fit(args: argparse.Namespace) -> int:
    from darkread.models.train.fit import fit, is_exported_network

    config = _fit_config(args)
    config.freeze_batchnorm = args.init is not None and is_exported_network(args.init)
    summary = fit(args.train_dir, args.run_dir, config, resume=not args.restart, init_checkpoint=args.init)
    print(json.dumps(summary, indent=1, default=float))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from darkread.models.train.pipeline import export_models

    checkpoint = args.checkpoint or args.run_dir / "best.pt"
    print(json.dumps(export_models(checkpoint, args.train_dir, args.models_dir, args.calibration_windows), indent=1))
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from darkread.models.train.pipeline import evaluate_and_card

    timings = {k: float(v) for k, v in (t.split("=", 1) for t in args.timing)}
    info = evaluate_and_card(args.run_dir, args.train_dir, args.val_dir, models_dir=args.models_dir,
                             timings=timings, eval_limit=args.limit, figure=args.figure)
    print(json.dumps({"overall": info["report"]["overall"], "by_lux": info["report"].get("by_lux"), "latency": info["latency"]}, indent=1))
    return 0


def _cmd_finetune(args: argparse.Namespace) -> int:
    from darkread.models.train.finetune import TuneConfig, annotate_missing, check_parts, finetune
    from darkread.models.train.onnx_weights import model_from_onnx

    if not args.recordings and not args.annotated:
        raise ValueError("nothing to tune on: give --annotated DIR... (from `darkread train annotate`) or RECORDINGS...")
    if not 0.0 <= args.synthetic_share < 1.0:
        raise ValueError(f"--synthetic-share {args.synthetic_share}: must be in [0, 1)")
    if args.anchor < 0:
        raise ValueError(f"--anchor {args.anchor}: must be >= 0")
    for path in [*args.recordings, *args.annotated, *(args.synthetic_dir or ())]:
        if not path.is_dir():
            raise FileNotFoundError(f"{path}: no such directory")
    train_only = tuple(part for part in (args.train_only or "").split(",") if part)
    if train_only:  # before minutes of annotating and loading, not after
        check_parts(model_from_onnx(args.base), train_only)
    dirs = list(args.annotated)
    if args.recordings:
        dirs += annotate_missing(args.recordings, args.layout, args.run_dir / "annotated", progress=not args.quiet)
    cfg = TuneConfig(lr=args.lr, steps=args.steps, minutes=args.minutes, batch_size=args.batch_size,
                     synthetic_share=args.synthetic_share if args.synthetic is None or args.synthetic > 0 else 0.0,
                     threads=args.threads, seed=args.seed, anchor_weight=args.anchor,
                     train_only=train_only)
    summary = finetune(dirs, args.base, args.run_dir, args.export, cfg=cfg, synthetic=args.synthetic,
                       synthetic_dirs=args.synthetic_dir or (), progress=not args.quiet)
    print(json.dumps(summary, indent=1, default=float))
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from darkread.lab.train.compare import compare
    from darkread.lab.train.placebo import write_placebo

    models = {"shipped" if args.base == MODELS_DIR / "binary_unet.onnx" else "base": args.base, args.name: args.model}
    if len(set(models)) < 2:
        raise ValueError(f"--name {args.name}: must differ from the base model's name")
    for path in models.values():
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such model file")
    for path in args.inputs:
        if not path.is_dir():
            raise FileNotFoundError(f"{path}: no such recording or shard directory")
    if args.placebos < 0:
        raise ValueError(f"--placebos {args.placebos}: must be >= 0")
    chance = [f"placebo{i}" for i in range(1, args.placebos + 1)]
    if args.name in chance:
        raise ValueError(f"--name {args.name}: taken by a placebo; choose another name")
    for i, name in enumerate(chance, start=1):  # seeds 1..N: the same placebos, and their cached reads, on every rerun
        models[name] = write_placebo(args.base, args.out / "placebos" / f"{name}.onnx", seed=i, scale=args.placebo_scale)
    compare(args.inputs, models, args.out, read=not args.no_read, backend=args.backend, group=args.group,
            chance=chance, jobs=args.jobs, progress=not args.quiet)
    print((args.out / "compare.md").read_text(encoding="utf-8"))
    return 0


def _cmd_rehearsal(args: argparse.Namespace) -> int:
    from darkread.lab.train.rehearsal import describe, make_rehearsal

    summary = make_rehearsal(args.out, count=args.recordings, seed=args.seed, every_ms=args.every_ms, seconds=args.seconds,
                             jobs=args.jobs, progress=not args.quiet, regime=args.regime)
    print(f"{args.out}: {describe(summary)}")
    return 0


def _cmd_band(args: argparse.Namespace) -> int:
    from darkread.lab.train.band import tune_across_band

    if not args.base.is_file():
        raise FileNotFoundError(f"--base {args.base}: no such model file")
    info = tune_across_band(args.base, args.work, args.export, jobs=args.jobs, progress=not args.quiet)
    tune = info["tune"]
    print("\n".join(f"{name} windows: {held}" for name, held in info["sets"].items()))
    print(f"{args.export}: tuned across the band in {tune['steps']} steps ({tune['seconds']:.0f} s) on "
          f"{tune['annotated_windows']} grounded and {tune['synthetic_windows']} standard windows; "
          f"ink F1 on the grounded windows {tune['monitor_f1_before']['annotated_training_windows']:.3f} -> "
          f"{tune['monitor_f1_after']['annotated_training_windows']:.3f}")
    return 0


def _cmd_placebo(args: argparse.Namespace) -> int:
    from darkread.lab.train.placebo import write_placebo

    if not args.base.is_file():
        raise FileNotFoundError(f"--base {args.base}: no such model file")
    if args.count < 1:
        raise ValueError(f"--count {args.count}: must be at least 1")
    written = [write_placebo(args.base, args.out.parent / f"{args.out.stem}{i}{args.out.suffix}" if args.count > 1 else args.out,
                             seed=args.seed + i, scale=args.scale) for i in range(args.count)]
    print("\n".join(str(p) for p in written))
    return 0


def _cmd_target(args: argparse.Namespace) -> int:
    from darkread.models.synth.marker_page import MarkerPageSpec, lay_out, text_lines, write_target

    try:
        text = Path(args.text).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileNotFoundError(f"--text {args.text}: no such file") from None
    spec = MarkerPageSpec(lines=text_lines(text, args.line_chars), font=args.font, xheight_mm=args.xheight_mm,
                          marker_mm=args.marker_mm)
    page = lay_out(spec)
    out, layout = write_target(args.out, page, dpi=args.dpi)
    w, h = page.size_mm
    print(f"{out}: {w:.1f} x {h:.1f} mm (print at 100 %, \"actual size\"), {len(page.markers)} markers, "
          f"{len(page.glyphs)} glyphs; layout -> {layout}")
    return 0


def _cmd_annotate(args: argparse.Namespace) -> int:
    from darkread.lab.truth import annotate_from_truth
    from darkread.models.train.annotate import AnnotateConfig, annotate_recording

    if not Path(args.recording).is_dir():
        raise FileNotFoundError(f"{args.recording}: no such recording directory")
    if args.truth:
        summary = annotate_from_truth(args.recording, args.out, every_ms=args.every_ms, max_windows=args.max_windows)
        print(json.dumps(summary, indent=1))
        return 0
    cfg = AnnotateConfig(window_every_ms=args.every_ms, max_windows=args.max_windows,
                         max_offset_ms=args.max_offset_ms, refine_offset=args.max_offset_ms > 0)
    summary = annotate_recording(args.recording, args.layout, args.out, cfg, progress=not args.quiet)
    print(json.dumps({k: v for k, v in summary.items() if k != "config"}, indent=1))
    return 0


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, not {value}")
    return value


def _synthetic_count(text: str) -> int | None:
    """A window count >= 0, or "all" (None)."""
    if text == "all":
        return None
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a count or 'all', not {text}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0 or 'all', not {text}")
    return value


def _positive_float(text: str) -> float:
    value = float(text)
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, not {text}")
    return value


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from darkread.models.train.calibrate import calibrate

    if not Path(args.val_dir).exists():
        raise FileNotFoundError(f"{args.val_dir}: no such shard directory (make one with `darkread synth dataset --split val`)")
    result = calibrate(args.val_dir, args.model, limit=args.limit)
    print(result.to_markdown())
    print(f"\nink temperature {result.temperature:g} by log-loss")
    if args.store is not None:
        from darkread.edge.reconstruct import default_model_path
        from darkread.models.train.calibrate import store_ink_temperature

        model = args.model or default_model_path()
        store_ink_temperature(model, args.store)
        print(f"{model}: ink temperature {args.store:g} stored (the edge reads it from the model)")
    return 0


def _cmd_all(args: argparse.Namespace) -> int:
    from darkread.models.train.pipeline import TRAINING_RECIPE, VALIDATION_RECIPE, reproduce

    info = reproduce(args.train_dir, args.val_dir, args.run_dir, config=_fit_config(args),
                     train_samples=args.train_samples or TRAINING_RECIPE[0].samples,
                     val_samples=args.val_samples or VALIDATION_RECIPE.samples, workers=args.threads)
    print(json.dumps({"overall": info["report"]["overall"], "timings_s": info["timings_s"]}, indent=1))
    return 0


def _add_fit(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fit", help="train on synthetic shards (time-budgeted, resumes from RUN_DIR/last.pt)")
    p.add_argument("train_dir", type=Path, nargs="*", default=[DEFAULT_TRAIN], metavar="TRAIN_DIR",
                   help=f"dataset(s) of shard-*.npz; several are mixed shard by shard (default {DEFAULT_TRAIN})")
    _add_fit_options(p)
    p.add_argument("--restart", action="store_true", help="ignore an existing last.pt and start fresh")
    p.add_argument("--init", type=Path, metavar="MODEL",
                   help="start from these weights instead of a fresh network: a checkpoint (.pt) or an exported "
                        "network (.onnx, e.g. models/binary_unet.onnx; its BatchNorms are folded, so they stay frozen)")
    p.add_argument("--teacher", type=Path, metavar="MODEL",
                   help="also learn this network's ink probability (distillation, 80 %% of the loss): e.g. a cheaper "
                        "head that reads like the shipped network")
    p.set_defaults(func=_cmd_fit)


def _add_export(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="ONNX fp32 + static int8 QDQ from a checkpoint")
    p.add_argument("--run-dir", type=Path, default=Path("runs/binary_unet"))
    p.add_argument("--checkpoint", type=Path, help="default RUN_DIR/best.pt")
    p.add_argument("--train-dir", type=Path, default=DEFAULT_TRAIN, help="int8 calibration windows come from here")
    p.add_argument("--calibration-windows", type=int, default=256)
    p.add_argument("--models-dir", type=Path, default=MODELS_DIR, help=f"where the .onnx files go (default {MODELS_DIR})")
    p.set_defaults(func=_cmd_export)


def _add_evaluate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="held-out scores by lux/motion vs the naive baseline, latency, figure, MODEL_CARD.md")
    p.add_argument("--run-dir", type=Path, default=Path("runs/binary_unet"), help="training run (history.json)")
    p.add_argument("--train-dir", type=Path, default=DEFAULT_TRAIN, help="baseline tuning windows come from here")
    p.add_argument("--val-dir", type=Path, default=DEFAULT_VAL)
    p.add_argument("--models-dir", type=Path, default=MODELS_DIR)
    p.add_argument("--limit", type=int, help="evaluate at most this many validation windows")
    p.add_argument("--figure", type=Path, default=FIGURE_PATH)
    p.add_argument("--timing", action="append", default=[], metavar="STEP=SECONDS", help="extra rows for the card's reproduction-time table")
    p.set_defaults(func=_cmd_evaluate)


def _add_finetune(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("finetune", help="fine-tune the shipped network on annotated recordings (mixed with synthetic windows), export ONNX",
                       description="Fine-tune from the shipped weights (BINARY_UNET.onnx read back into torch) on the windows "
                                   "`darkread train annotate` labelled from the page's pose, with synthetic standard-regime "
                                   "windows in every batch so the network does not forget, at a low learning rate within a "
                                   "step and time budget. Writes RUN_DIR/finetune.json, RUN_DIR/tuned.pt and the ONNX "
                                   "(--export; default RUN_DIR/tuned.onnx) for `darkread read --model`. Compare before/after "
                                   "on recordings it was not tuned on with `darkread train compare`.")
    p.add_argument("recordings", type=Path, nargs="*", metavar="RECORDING",
                   help="recordings of a marker page to annotate first (into RUN_DIR/annotated/; --layout)")
    p.add_argument("--annotated", type=Path, nargs="+", default=[], metavar="DIR",
                   help="directories written by `darkread train annotate` (shard-00000.npz)")
    p.add_argument("--layout", type=Path, help="page layout for RECORDINGs (default each RECORDING/page.layout.json)")
    p.add_argument("--base", type=Path, default=MODELS_DIR / "binary_unet.onnx", help="starting weights (default: the shipped model)")
    p.add_argument("--export", type=Path, help="the tuned network as ONNX (default RUN_DIR/tuned.onnx)")
    p.add_argument("--run-dir", type=Path, default=Path("runs/finetune"))
    p.add_argument("--synthetic", type=_synthetic_count, default=600, metavar="N|all",
                   help="synthetic standard-regime windows to mix in (default 600; 0 = none; all = every window of --synthetic-dir)")
    p.add_argument("--synthetic-dir", type=Path, nargs="+", metavar="DIR",
                   help="take them from these directories, in turn, instead of simulating: `darkread synth dataset` (random "
                        "page crops) and `darkread train rehearsal` (windows of simulated standard-regime reading, what the "
                        "glasses cut); --synthetic all uses every window of them")
    p.add_argument("--synthetic-share", type=float, default=0.5, help="share of every batch that is synthetic (default 0.5)")
    p.add_argument("--train-only", metavar="PARTS",
                   help="tune only these top-level parts of the network, comma-separated (e.g. stem,down1: where a "
                        "sensor's difference enters); the rest stay as they were (default: all)")
    p.add_argument("--anchor", type=float, default=0.0, metavar="W",
                   help="on the synthetic windows, also pull toward the starting network's own answer, weighted W "
                        "against the truth (learning without forgetting; default 0 = off)")
    p.add_argument("--lr", type=float, default=2e-4, help="peak learning rate (default 2e-4; training used 3e-3)")
    p.add_argument("--steps", type=int, default=1500, help="at most this many steps (default 1500)")
    p.add_argument("--minutes", type=float, default=20.0, help="wall-time budget (default 20)")
    p.add_argument("--batch-size", type=int, default=16)
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads (default 1)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_finetune)


def _add_compare(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="before/after: ink F1 and end-to-end CER of the shipped and a tuned model",
                       description="Score the shipped network and a tuned one (--model) on recordings they were not tuned on: "
                                   "ink F1 of the windows the glasses cut against the simulator's ground truth (a recording "
                                   "with pose_truth.npz and page.layout.json or page_ink.npz, as `darkread synth recording` "
                                   "writes them, or a shard directory's own targets), and the "
                                   "CER of reading each recording end to end exactly as `darkread read --model` does. Writes "
                                   "OUT/compare.json, OUT/compare.md (printed) and OUT/compare.png; reads are cached per model "
                                   "under OUT/cache, so a rerun resumes.")
    p.add_argument("inputs", type=Path, nargs="+", metavar="INPUT", help="recording directories, or shard directories (ink F1 only)")
    p.add_argument("--model", type=Path, required=True, help="the tuned ONNX (from `darkread train finetune --export`)")
    p.add_argument("--base", type=Path, default=MODELS_DIR / "binary_unet.onnx", help="the model before (default: the shipped one)")
    p.add_argument("--name", default="tuned", help="the tuned model's name in the tables (default tuned)")
    p.add_argument("--out", type=Path, default=Path("runs/compare"), help="output directory (default runs/compare)")
    p.add_argument("--no-read", action="store_true", help="ink F1 only, no end-to-end reads")
    p.add_argument("--backend", default="local", help="OCR backend of the reads (default local)")
    p.add_argument("--group", help="one group name for all inputs in the summary (default: by regime and lux)")
    p.add_argument("--placebos", type=int, default=0, metavar="N",
                   help="also read N placebos of the base (`darkread train placebo`, seeds 1..N, into OUT/placebos) and give "
                        "their range beside the tuned model's figures and whether it falls below, inside or above it "
                        "(default 0; each costs as much as reading the tuned model)")
    p.add_argument("--placebo-scale", type=float, default=0.005, help="the placebos' relative weight perturbation (default 0.005)")
    p.add_argument("--jobs", type=_positive_int, default=1, help="inputs scored at once, each in its own process (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_compare)


def _add_placebo(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("placebo", help="networks that learned nothing (the base's weights slightly perturbed): the chance spread of a before/after",
                       description="Write copies of the base network whose weights are each scaled by (1 + SCALE x N(0,1)): "
                                   "networks that learned nothing. `darkread train compare --model PLACEBO` on the same "
                                   "recordings shows how far end-to-end CER moves by chance (a frame kept or fused a little "
                                   "differently can flip a page); a tuned network's change means something where it leaves "
                                   "that spread. With --count N: OUT's name gets 0..N-1 (seeds SEED..SEED+N-1).")
    p.add_argument("--out", type=Path, required=True, help="the placebo ONNX to write (with --count: the name numbered)")
    p.add_argument("--base", type=Path, default=MODELS_DIR / "binary_unet.onnx", help="the network to perturb (default: the shipped one)")
    p.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    p.add_argument("--scale", type=float, default=0.005, help="relative size of the perturbation (default 0.005)")
    p.add_argument("--count", type=int, default=1, help="how many placebos (default 1)")
    p.set_defaults(func=_cmd_placebo)


def _add_rehearsal(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("rehearsal", help="windows of simulated reading in the shipped network's own sensor regime, for a fine-tune to rehearse",
                       description="Simulate reading sessions in the standard sensor regime (the one the shipped network was "
                                   "trained on: three lines of training text at 5-50 lux, still, normal and walking head "
                                   "motion), cut every session's windows as the glasses do, label them from the simulator's "
                                   "own pose and ink (`train annotate --truth`), and write them as one shard directory for "
                                   "`darkread train finetune --synthetic-dir`. Mixed into a fine-tune they keep the network "
                                   "reading the old regime as it did (docs/finetune.md). With --regime grounded the sessions "
                                   "are the grounded sensor's, the windows `darkread train band` learns from. An interrupted "
                                   "run resumes.")
    p.add_argument("out", type=Path, help="output shard directory")
    p.add_argument("--recordings", type=_positive_int, default=18, help="reading sessions (default 18: 6 lux levels x 3 motions)")
    p.add_argument("--seed", type=int, default=601, help="the first session's seed (default 601)")
    p.add_argument("--seconds", type=_positive_float, default=2.5, help="length of a session (default 2.5)")
    p.add_argument("--every-ms", type=_positive_float, default=10.0, help="one window per this interval (default 10)")
    p.add_argument("--regime", choices=("standard", "grounded"), default="standard",
                   help="standard (default): the shipped network's own sensor regime; grounded: the sensor and head motion "
                        "of published measurements at 3-30 lux, K drawn over its band, half the sessions at the dark bias "
                        "profile (36 sessions cover lux x motion x biases once)")
    p.add_argument("--jobs", type=_positive_int, default=1, help="sessions simulated at once (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_rehearsal)


def _add_band(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("band", help="tune a network across the sensor's plausible band (grounded reading windows, both bias profiles)",
                       description="Tune a network (default the shipped one) on what the glasses cut while someone reads "
                                   "under the grounded sensor model: 36 simulated reading sessions at 3-30 lux, each with "
                                   "its photoreceptor K drawn over 40-400 Hz per chip-lux, half at the dark bias profile, "
                                   "with the standard regime's reading windows and page crops rehearsed in every batch "
                                   "(lab/train/band.py BAND_RECIPE; what it reads: docs/finetune.md). The window sets "
                                   "are made under --work when absent (about 25 min on one core) and kept.")
    p.add_argument("--base", type=Path, default=MODELS_DIR / "binary_unet.onnx", help="the network to tune (default the shipped one)")
    p.add_argument("--work", type=Path, default=Path("runs/band"), help="window sets and the tune's run (default runs/band)")
    p.add_argument("--export", type=Path, default=Path("runs/band/binary_unet_band.onnx"), help="the tuned network (ONNX)")
    p.add_argument("--jobs", type=_positive_int, default=1, help="reading sessions simulated at once (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_band)


def _add_target(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("target", help="a printable page: the text with ArUco markers around it, and its layout",
                       description="Lay out a text file with ArUco markers around it (the synthesiser's page renderer, the "
                                   "calibration's marker dictionary) as a PDF or PNG, and write page.layout.json beside it: "
                                   "marker ids and corners and every glyph's box in page millimetres. Print it at 100 % "
                                   "(\"actual size\"), record it with the glasses, then `darkread train annotate`.")
    p.add_argument("--text", required=True, metavar="FILE", help="the text to print (UTF-8; long lines are wrapped)")
    p.add_argument("--out", required=True, type=Path, metavar="PAGE.pdf|PAGE.png", help="what to write (layout: PAGE.layout.json)")
    p.add_argument("--font", default="DejaVu Sans", help="font face (default DejaVu Sans; see models/synth/fonts.py)")
    p.add_argument("--xheight-mm", type=float, default=2.4, help="lower-case x-height in mm (default 2.4, about 12 pt)")
    p.add_argument("--marker-mm", type=float, default=12.0, help="marker side in mm (default 12)")
    p.add_argument("--line-chars", type=int, default=48, help="wrap lines longer than this (default 48)")
    p.add_argument("--dpi", type=float, default=300.0, help="PNG resolution (default 300; the PDF is always at size)")
    p.set_defaults(func=_cmd_target)


def _add_annotate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("annotate", help="targets for every window of a recording of a marker page, from the page's pose",
                       description="Find the page's ArUco markers in event images, fit the page-to-sensor homography over "
                                   "time (refined on the events, interpolated between poses), choose the time offset that "
                                   "best matches the page's edges to the windows' events, and render every 1600-event "
                                   "window's ink target. Writes OUT/shard-00000.npz (the training shard format) and "
                                   "OUT/annotation.json (share annotated, detection rate; the residual against the "
                                   "simulator's pose when the recording has pose_truth.npz).")
    p.add_argument("recording", type=Path, help="recording directory (events.raw, general_eye_gaze.csv, calibration.json)")
    p.add_argument("--layout", type=Path, help="the page's layout (default RECORDING/page.layout.json)")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument("--every-ms", type=float, default=40.0, help="one window per this interval (default 40)")
    p.add_argument("--max-windows", type=int, default=400)
    p.add_argument("--max-offset-ms", type=float, default=8.0, help="time offset search range, +- ms (default 8; 0 = off)")
    p.add_argument("--truth", action="store_true",
                   help="a synthetic recording (any page `darkread synth recording` wrote): label every window from the "
                        "simulator's own pose and ink instead of markers, its events deblurred as on the edge")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_annotate)


def _add_calibrate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="the ink temperature: sigmoid(logits / T) fitted by log-loss on held-out windows",
                       description="Fit the temperature that makes the network's ink probability mean what it says (the "
                                   "on-change mode averages it over a view's frames) on a shard directory's windows, and "
                                   "print the log-loss per temperature and a reliability table.")
    p.add_argument("val_dir", type=Path, nargs="?", default=DEFAULT_VAL, help=f"shard directory (default {DEFAULT_VAL})")
    p.add_argument("--model", type=Path, help="ONNX model (default: the shipped one)")
    p.add_argument("--limit", type=_positive_int, default=500, help="windows to use (default 500)")
    p.add_argument("--store", type=_positive_float, metavar="T",
                   help="write this temperature into the model's metadata, where the edge reads it (a network "
                        "without one is read at 1.5)")
    p.set_defaults(func=_cmd_calibrate)


def _add_all(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("all", help="reproduce the shipped model from scratch: synth -> fit -> export -> int8 -> evaluate -> card")
    p.add_argument("--train-dir", type=Path, default=DEFAULT_TRAIN)
    p.add_argument("--val-dir", type=Path, default=DEFAULT_VAL)
    p.add_argument("--train-samples", type=_positive_int, metavar="N",
                   help="windows of the recipe's first training set; its other sets are scaled alike "
                        "(default: the recipe's, pipeline.TRAINING_RECIPE)")
    p.add_argument("--val-samples", type=_positive_int, metavar="N",
                   help="validation windows (default: the recipe's, pipeline.VALIDATION_RECIPE)")
    _add_fit_options(p)
    p.set_defaults(func=_cmd_all, minutes=90.0)  # the shipped network's budget


def register(subparsers: argparse._SubParsersAction) -> None:
    train = subparsers.add_parser("train", help="train, export and evaluate the reconstruction network",
                                  description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = train.add_subparsers(dest="train_command", metavar="STEP")
    train.set_defaults(func=lambda _args: (train.print_help(), 2)[1])
    for add in (_add_fit, _add_export, _add_evaluate, _add_finetune, _add_band, _add_compare, _add_placebo, _add_rehearsal, _add_target,
                _add_annotate, _add_calibrate, _add_all):
        add(sub)

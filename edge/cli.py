"""``darkread edge run``: the edge daemon (camera or replay -> foveated frames -> cloud).

Light module: heavy imports happen inside the handler.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from darkread.core.redact import redact
from darkread.edge.config import INFER_MODES

RUN_HELP = """\
Run the edge pipeline: read events (the EVK4 camera, or a recording replayed at wall-clock
speed or faster), foveate around the gaze, reconstruct text frames with the ONNX U-Net and
stream them to the cloud over a websocket. Frames are spooled to disk until the cloud
acknowledges them, so network drops and restarts lose nothing: by default under the user's
state directory ($XDG_STATE_HOME/darkread/spool, else ~/.local/state/darkread/spool), one edge
at a time; --spool :memory: keeps them in memory only (lost when the run ends unsent).

Settings come from --config (TOML, see edge/systemd/edge.toml), then the environment
(DARKREAD_EDGE_<SECTION>_<KEY>, e.g. DARKREAD_EDGE_UPLINK_API_KEY), then these options.
A replay exits when the recording ends and the spool is drained (or --drain-timeout passes).
A run that fails ends with one line "darkread: error: ..." saying what failed, and its exit
status says which way: 1 bad input or a failed run (a recording that cannot be read, the cloud
refused the stream), 3 the cloud did not take every message (they stay in the spool, or were
lost with --spool :memory:), 4 the spool cannot be written (read-only or full disk, another
edge holds it). URLs are logged with any key in them redacted.

Example:
  darkread edge run --replay darkread/data/sample_recording \\
      --cloud ws://127.0.0.1:8000/v1/stream --api-key KEY --speed max --spool /tmp/spool
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    edge = subparsers.add_parser("edge", help="the glasses-side daemon", description="The glasses-side daemon.")
    commands = edge.add_subparsers(dest="edge_command", metavar="COMMAND")
    run = commands.add_parser(
        "run", help="run the edge pipeline (camera or replay) and stream to the cloud",
        description=RUN_HELP, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument("--config", metavar="TOML", help="configuration file (edge.toml)")
    run.add_argument("--replay", metavar="RECORDING", help="replay a recording directory or .raw file instead of the camera")
    run.add_argument("--gaze-csv", metavar="CSV", help="gaze CSV for a bare .raw replay")
    run.add_argument("--calibration", metavar="JSON", help="calibration.json (bare .raw replay, or the camera)")
    run.add_argument(
        "--speed", metavar="N|max", type=_speed_option,
        help="replay pacing: 1 = wall clock (default), 2 = twice as fast, max = as fast as inference allows (no skips)",
    )
    run.add_argument("--gaze", choices=["recording", "csv", "udp", "aria"], help="gaze source (default: the recording's for a replay)")
    run.add_argument("--gaze-port", type=int, metavar="PORT", help="UDP port of the gaze feed")
    run.add_argument(
        "--cloud", metavar="URL", action="append",
        help="websocket URL, e.g. ws://127.0.0.1:8000/v1/stream; repeat it (or separate with commas) for several "
        "cloud instances on one database: on a failed connect or a closed connection the edge moves to the next",
    )  # fmt: skip
    run.add_argument("--api-key", metavar="KEY", help="cloud API key (prefer DARKREAD_EDGE_UPLINK_API_KEY)")
    run.add_argument("--mode", choices=["frames", "pages"], help="send frames (default) or pages stitched on the glasses")
    run.add_argument(
        "--spool", metavar="DIR",
        help="spool directory for unacknowledged frames (default: $XDG_STATE_HOME/darkread/spool, else "
             "~/.local/state/darkread/spool); ':memory:' keeps them in memory only (lost at exit if unsent)",
    )
    run.add_argument("--session", metavar="ID", help="session id (default: resume the spool's, else a new one)")
    run.add_argument("--model", metavar="ONNX", help="reconstruction model (default: the shipped one)")
    run.add_argument("--lossless", action="store_true", help="never skip windows: the reader waits for inference")
    run.add_argument(
        "--infer", choices=INFER_MODES,
        help="on-change (default): infer during fixations when the view changed and send one fused view per "
             "fixation (a tenth of the inferences and bytes); every-window: infer every n_events foveated events and send every frame",
    )
    run.add_argument("--metrics-port", type=int, metavar="PORT", help="serve Prometheus metrics on 127.0.0.1:PORT")
    run.add_argument("--drain-timeout", type=float, metavar="S", help="seconds to wait for acks at exit (default 30)")
    run.set_defaults(func=_run)
    edge.set_defaults(func=lambda args: edge.print_help() or 2)


def _speed_option(text: str) -> str:
    """``--speed`` as given, once it parses (argparse then names the option in its error)."""
    from darkread.edge.sources.replay import parse_speed

    try:
        parse_speed(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def overrides_from_args(args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """Command-line options as ``{section: {key: value}}`` config overrides."""
    from darkread.edge.sources.replay import parse_speed

    out: dict[str, dict[str, Any]] = {"source": {}, "gaze": {}, "pipeline": {}, "uplink": {}, "metrics": {}}
    if args.replay:
        out["source"].update(kind="replay", path=args.replay)
        if not args.gaze:
            out["gaze"]["kind"] = "recording"  # the replayed recording's own gaze (or --gaze-csv)
    if args.gaze_csv:
        out["source"]["gaze_csv"] = args.gaze_csv
    if args.calibration:
        out["source"]["calibration"] = args.calibration
    if args.speed is not None:
        speed = parse_speed(args.speed)
        out["source"]["speed"] = 0.0 if speed is None else speed
    if args.gaze:
        out["gaze"]["kind"] = args.gaze
    if args.gaze_port is not None:
        out["gaze"]["udp_port"] = args.gaze_port
    if args.cloud:
        out["uplink"]["url"] = ",".join(args.cloud)
    for option, key in (("api_key", "api_key"), ("mode", "mode"), ("spool", "spool_dir"),
                        ("session", "session_id"), ("drain_timeout", "drain_timeout_s")):
        value = getattr(args, option)
        if value is not None:
            out["uplink"][key] = value
    if args.model:
        out["pipeline"]["model"] = args.model
    if args.lossless:
        out["pipeline"]["lossless"] = True
    if args.infer:
        out["pipeline"]["infer"] = args.infer
    if args.metrics_port is not None:
        out["metrics"]["port"] = args.metrics_port
    return {section: values for section, values in out.items() if values}


def _run(args: argparse.Namespace) -> int:
    """Run the daemon; a run that did not deliver everything raises one error saying what failed
    and what the spool still holds (the command line prints it as its last line)."""
    from darkread.core.errors import DarkreadError
    from darkread.core.redact import redact_handlers
    from darkread.edge.builder import build_edge
    from darkread.edge.config import load_config
    from darkread.edge.daemon import Daemon
    from darkread.edge.journal import use_journal_format_if_under_systemd
    from darkread.edge.notify import Notifier

    use_journal_format_if_under_systemd()
    redact_handlers()  # every library's log lines too (websockets names the URL it connects to)
    config = load_config(args.config, overrides=overrides_from_args(args))
    notifier = Notifier()
    edge = build_edge(config, watchdog=notifier.watchdog_tick)
    if not args.quiet:
        print(streaming_line(config.uplink.url, edge.uplink.session_id), file=sys.stderr, flush=True)
    try:
        status = Daemon(edge, notifier, shutdown_timeout_s=config.uplink.drain_timeout_s).run()
    except DarkreadError as exc:
        failure = edge.with_left_behind(exc)
        if failure is exc:
            raise
        raise failure from exc
    if status != 0:
        raise edge.undelivered_error()
    return 0


def live_page_url(stream_url: str, session_id: str) -> str:
    """The cloud's live page of a session, from the websocket URL the edge streams to."""
    scheme, _, rest = stream_url.strip().partition("://")
    host = rest.split("/", 1)[0]
    return f"{'https' if scheme == 'wss' else 'http'}://{host}/sessions/{session_id}"


def streaming_line(urls: str, session_id: str) -> str:
    """What ``edge run`` says at start: the session it streams to, where, and its live page (keys in
    the URLs redacted: the line goes to the journal)."""
    from darkread.edge.uplink import split_urls

    first, *others = (redact(url) for url in split_urls(urls))  # at least one: the config is validated
    failover = f" (then {', '.join(others)})" if others else ""
    return f"streaming session {session_id} to {first}{failover}; live page: {live_page_url(first, session_id)}"

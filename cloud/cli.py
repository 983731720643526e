"""``darkread cloud serve`` and ``darkread cloud keys``: run the service, manage its API keys.

Light module: heavy imports happen in the handlers.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from darkread.cloud.auth import KeyRing
    from darkread.cloud.settings import Settings

from darkread.cloud.ocr.base import OCR_BACKENDS

KEYS_HELP = """\
API keys per device, stored hashed in <data dir>/keys.json (DARKREAD_KEYS_FILE elsewhere).
Scopes: stream (open and stream its own device's sessions), read (list, read and ask about its
own device's sessions), admin (everything, every device, DELETE and /metrics). A running
service picks up added and revoked keys without a restart.

  darkread cloud keys add --device glasses-1 --scope stream,read    prints the key, once
  darkread cloud keys list
  darkread cloud keys revoke KEY_ID
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    cloud = subparsers.add_parser(
        "cloud",
        help="the cloud service (websocket ingest, stitching, OCR)",
        description="The darkread cloud service. Settings also come from DARKREAD_* environment variables.",
    )
    commands = cloud.add_subparsers(dest="cloud_command", metavar="COMMAND", required=True)
    serve = commands.add_parser(
        "serve",
        help="serve WS /v1/stream and the REST API with uvicorn",
        description=(
            "Serve the darkread cloud: WS /v1/stream for the glasses, POST /v1/sessions/{id}/ask, "
            "GET /v1/sessions/{id}/page.png, /healthz, /readyz, /metrics (admin key) and, with "
            "DARKREAD_API_DOCS=1, the API docs at /docs. Without any key (DARKREAD_API_KEY or "
            "`darkread cloud keys add`) only 127.0.0.1 is served. Every option can also be set as an "
            "environment variable (DARKREAD_DATA_DIR, DARKREAD_DATABASE_URL, DARKREAD_API_KEY, DARKREAD_OCR_BACKEND, ...)."
        ),
    )
    serve.add_argument("--host", default="127.0.0.1",
                       help="address to listen on (default 127.0.0.1; any other address needs a key)")
    serve.add_argument("--port", type=int, default=8000, help="TCP port (default 8000)")
    serve.add_argument("--data-dir", type=Path, help="where the SQLite database and page images live")
    serve.add_argument(
        "--database-url", metavar="URL",
        help="postgresql://user:password@host:port/db: sessions in PostgreSQL, shared by every instance "
        "pointed at it (prefer DARKREAD_DATABASE_URL: arguments show up in ps); default: SQLite in --data-dir",
    )  # fmt: skip
    serve.add_argument("--api-key", help="an admin API key (prefer DARKREAD_API_KEY: arguments show up in ps)")
    serve.add_argument("--insecure", action="store_true",
                       help="serve other hosts without any key (a closed test network only)")
    serve.add_argument("--ocr", choices=OCR_BACKENDS, help="OCR engine (default: local, the embedded rapidocr)")
    serve.set_defaults(func=_serve)

    keys = commands.add_parser("keys", help="add, list and revoke per-device API keys", description=KEYS_HELP,
                               formatter_class=argparse.RawDescriptionHelpFormatter)
    key_commands = keys.add_subparsers(dest="keys_command", metavar="ACTION", required=True)
    add = key_commands.add_parser("add", help="create a key for a device and print it (once)")
    add.add_argument("--device", required=True, help="the device id the key belongs to (hello.device_id)")
    add.add_argument("--scope", default="stream,read", help="comma-separated: stream, read, admin (default stream,read)")
    listing = key_commands.add_parser("list", help="the keys (ids, devices, scopes; never the keys)")
    revoke = key_commands.add_parser("revoke", help="revoke a key by its id")
    revoke.add_argument("key_id", help="the id shown by `keys list` (the 8 hex digits after drk_)")
    for sub in (add, listing, revoke):
        sub.add_argument("--data-dir", type=Path, help="the service's data directory (default: DARKREAD_DATA_DIR)")
    add.set_defaults(func=_keys_add)
    listing.set_defaults(func=_keys_list)
    revoke.set_defaults(func=_keys_revoke)


def _settings(args: argparse.Namespace) -> Settings:
    """Settings from the environment and options; a bad value is one line and exit 2."""
    from pydantic import ValidationError

    from darkread.cloud.settings import Settings

    overrides: dict[str, Any] = {}  # option values, as argparse parsed them
    for option, field in (("data_dir", "data_dir"), ("api_key", "api_key"), ("database_url", "database_url"),
                          ("ocr", "ocr_backend")):  # fmt: skip
        value = getattr(args, option, None)
        if value is not None:
            overrides[field] = value
    if getattr(args, "insecure", False):
        overrides["insecure"] = True
    try:
        return Settings(**overrides)
    except ValidationError as exc:
        first = exc.errors()[0]
        raise _UsageError(f"{'.'.join(map(str, first['loc'])) or 'settings'}: {first['msg']}") from None


class _UsageError(Exception):
    """A configuration mistake: printed as one line, exit status 2."""


def _fail(message: str) -> int:
    print(f"darkread: error: {message}", file=sys.stderr)
    return 2


def _serve(args: argparse.Namespace) -> int:
    import logging

    from darkread.cloud.auth import MIN_API_KEY_CHARS, KeyRing, is_loopback

    try:
        settings = _settings(args)
    except _UsageError as exc:
        return _fail(str(exc))
    has_keys = settings.api_key is not None or bool(KeyRing(settings.keys_path()))
    if not has_keys and not is_loopback(args.host) and not args.insecure:
        return _fail(
            f"refusing to serve {args.host} without an API key: set DARKREAD_API_KEY (an admin key) or add device "
            "keys with `darkread cloud keys add --device ID --scope stream,read`; or bind 127.0.0.1, or pass "
            "--insecure on a closed network"
        )
    api_key = settings.api_key
    if api_key is not None and len(api_key.get_secret_value()) < MIN_API_KEY_CHARS and not is_loopback(args.host):
        return _fail(
            f"refusing to serve {args.host} with a {len(api_key.get_secret_value())}-character API key: beyond "
            f"loopback DARKREAD_API_KEY must have at least {MIN_API_KEY_CHARS} characters (or use `darkread cloud "
            "keys add`)"
        )

    import uvicorn

    from darkread.cloud import datadir
    from darkread.cloud.app import create_app, live_config
    from darkread.cloud.errors import DataDirError
    from darkread.cloud.server import WEBSOCKET_OPTIONS

    try:  # before uvicorn: a bad data dir is one line, not a start-up traceback
        datadir.check_data_dir(settings.data_dir)
        held = datadir.acquire(settings.data_dir)
    except DataDirError as exc:
        print(f"darkread: error: {exc}", file=sys.stderr)
        return 1
    from darkread.cloud.confidence import load_model
    from darkread.cloud.errors import ConfidenceModelError, StoreError

    # a wrong database URL or password (said without the password), a broken line-confidence model:
    # one line, before uvicorn starts (the model loaded here is the one the sessions take from the cache)
    try:
        if settings.database_url is not None:
            from darkread.cloud.store.postgres import migrate_database

            migrate_database(settings.database_url.get_secret_value())
        load_model(live_config(settings).confidence_model)
    except (StoreError, ConfidenceModelError) as exc:
        datadir.release(held)
        print(f"darkread: error: {exc}", file=sys.stderr)
        return 1
    app = create_app(settings)
    # uvicorn refuses larger websocket messages itself (close 1009); leave room so that our own
    # check answers first with an error message naming the limit.
    uvicorn.run(
        app,
        host=args.host,
        port=args.port,
        ws_max_size=settings.max_message_bytes + 64 * 1024,
        log_level=logging.getLevelName(logging.getLogger().getEffectiveLevel()).lower(),  # follows -v / -q
        access_log=False,
        timeout_graceful_shutdown=settings.shutdown_timeout_s,  # type: ignore[arg-type]  # uvicorn says int; it waits with asyncio, a float works
        log_config=None,  # uvicorn logs through darkread's handler (one format)
        **WEBSOCKET_OPTIONS,
    )
    datadir.release(held)
    return 0


def _keyring(args: argparse.Namespace) -> KeyRing:
    from darkread.cloud.auth import KeyRing

    settings = _settings(args)
    return KeyRing(settings.keys_path())


def _keys_add(args: argparse.Namespace) -> int:
    from darkread.cloud.auth import parse_scopes

    try:
        scopes = parse_scopes(args.scope)
        ring = _keyring(args)
    except (ValueError, _UsageError) as exc:
        return _fail(str(exc))
    key = ring.add(args.device, scopes)
    print(key)
    print(f"key for device {args.device!r} ({', '.join(sorted(s.value for s in scopes))}) added to "
          f"{ring.path}; it is shown only now", file=sys.stderr)
    return 0


def _keys_list(args: argparse.Namespace) -> int:
    import time

    try:
        records = _keyring(args).records()
    except (ValueError, _UsageError) as exc:
        return _fail(str(exc))
    for record in records:
        created = time.strftime("%Y-%m-%d %H:%M", time.gmtime(record.created_s))
        print(f"{record.key_id}  {record.device:<24} {','.join(sorted(s.value for s in record.scopes)):<18} {created} UTC")
    return 0


def _keys_revoke(args: argparse.Namespace) -> int:
    try:
        revoked = _keyring(args).revoke(args.key_id)
    except (ValueError, _UsageError) as exc:
        return _fail(str(exc))
    if not revoked:
        return _fail(f"no key with id {args.key_id!r} (see `darkread cloud keys list`)")
    print(f"revoked {args.key_id}")
    return 0

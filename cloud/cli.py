"""``darkread cloud serve``: run the ingest + OCR service (heavy imports happen in the handler)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
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
            "GET /v1/sessions/{id}/page.png, /healthz, /readyz, /metrics and the API docs at /docs. "
            "Every option can also be set as an environment variable (DARKREAD_DATA_DIR, DARKREAD_DATABASE_URL, DARKREAD_API_KEY, "
            "DARKREAD_OCR_BACKEND, DARKREAD_GOOGLE_API_KEY, DARKREAD_OPENAI_API_KEY, ...)."
        ),
    )
    serve.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; 0.0.0.0 in containers)")
    serve.add_argument("--port", type=int, default=8000, help="TCP port (default 8000)")
    serve.add_argument("--data-dir", type=Path, help="where the SQLite database and page images live")
    serve.add_argument(
        "--database-url", metavar="URL",
        help="postgresql://user:password@host:port/db: sessions in PostgreSQL, shared by every instance "
        "pointed at it (prefer DARKREAD_DATABASE_URL: arguments show up in ps); default: SQLite in --data-dir",
    )  # fmt: skip
    serve.add_argument("--api-key", help="required API key (prefer DARKREAD_API_KEY: arguments show up in ps)")
    serve.add_argument(
        "--ocr", choices=("local", "tesseract", "google", "openai"), help="OCR engine (default: local rapidocr)"
    )
    serve.set_defaults(func=_serve)


def _serve(args: argparse.Namespace) -> int:
    import logging

    import uvicorn

    from darkread.cloud.app import create_app
    from darkread.cloud.settings import Settings

    overrides: dict[str, object] = {}
    if args.data_dir is not None:
        overrides["data_dir"] = args.data_dir
    if args.api_key is not None:
        overrides["api_key"] = args.api_key
    if args.database_url is not None:
        overrides["database_url"] = args.database_url
    if args.ocr is not None:
        overrides["ocr_backend"] = args.ocr
    settings = Settings(**overrides)  # type: ignore[arg-type]
    if settings.database_url is not None:
        from darkread.cloud.store.postgres import migrate_database

        migrate_database(settings.database_url.get_secret_value())  # a wrong URL: one line, before uvicorn starts
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
    )
    return 0

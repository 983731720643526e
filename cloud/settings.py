"""Cloud service settings, read from ``DARKREAD_*`` environment variables (or a ``.env`` file)."""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from darkread.proto.messages import DEFAULT_MAX_MESSAGE_BYTES

from .ocr.base import OcrBackendName
from .origins import normalise_origin
from .speech import VOICE_NAME_PATTERN, Voice

OCR_PROMPT = (
    "Transcribe all text in this image exactly, line by line, top to bottom. "
    "Output only the text, with no commentary."
)


class Settings(BaseSettings):
    """Every knob of the service. Secrets are ``SecretStr`` so they never appear in logs or reprs."""

    model_config = SettingsConfigDict(env_prefix="DARKREAD_", env_file=".env", extra="ignore")

    data_dir: Path = Field(Path("darkread-data"), description="SQLite database and page images live here")
    api_key: SecretStr | None = Field(
        None, description="one admin key; unset and no keys file = loopback clients only (see auth.py)"
    )
    keys_file: Path | None = Field(None, description="per-device keys (default: <data_dir>/keys.json)")
    insecure: bool = Field(False, description="serve clients on other hosts without any key (never in production)")
    api_docs: bool = Field(False, description="serve /docs, /redoc and /openapi.json")
    metrics_public: bool = Field(False, description="serve /metrics without a key (else an admin key is needed)")
    allowed_origins: Annotated[list[str], NoDecode] = Field(
        default_factory=list,
        description="web origins (https://host[:port]) whose pages may call the API besides the service's own; "
        "JSON list or comma-separated",
    )
    database_url: SecretStr | None = Field(
        None,
        description="postgresql://user:password@host:port/db: keep sessions in PostgreSQL (several instances "
        "share it); unset = SQLite in data_dir",
    )

    store_timeout_s: float = Field(
        3.0, gt=0, description="longest a request waits for a database connection before answering 503"
    )
    store_read_threads: int = Field(4, ge=1, description="threads reading the SQLite store (apart from speech and OCR)")
    ready_timeout_s: float = Field(1.0, gt=0, description="/readyz answers within this (a probe's timeout)")
    sse_per_key: int = Field(8, ge=1, description="event streams (GET .../events) one key may hold open at once")

    # Stream limits.
    max_message_bytes: int = Field(DEFAULT_MAX_MESSAGE_BYTES, ge=1024, le=64 * 1024 * 1024)
    max_in_flight: int = Field(64, ge=1, description="unacked messages per connection before reading pauses")
    hello_timeout_s: float = Field(10.0, gt=0, description="time a client has to send hello")
    shutdown_timeout_s: float = Field(
        10.0, gt=0, description="graceful shutdown deadline: then open connections are cancelled and the store let go"
    )

    # Live pages.
    live_idle_s: float = Field(300.0, gt=0, description="a session's pages leave memory after this idle time")
    session_expire_s: float = Field(
        0.0, ge=0, description="sessions idle this long are deleted with everything stored; 0 keeps them"
    )
    ask_catch_up_s: float = Field(
        0.3, ge=0, description="an ask waits at most this for frames stored before it, then reads the page as stitched so far"
    )
    page_lost_after_s: float = Field(0.5, gt=0, description="registration lost this long (event time) starts a page")
    max_page_pixels: int = Field(2_000_000, ge=10_000, description="a page whose canvas outgrows this starts anew")
    min_stitch_gap_ms: float = Field(
        0.0, ge=0, description="skip frames this close in time to the last stitched one at the same gaze (0 = stitch all)"
    )
    stitch_threads: int = Field(2, ge=1, description="threads stitching frames into pages (all sessions)")
    ocr_threads: int = Field(
        1, ge=1, description="threads rendering and reading pages (all sessions), each with its own offline OCR engine: up to one per core"
    )

    # OCR. "local" is the embedded rapidocr engine.
    ocr_backend: OcrBackendName = "local"
    ocr_lexicon: bool = Field(
        True, description="correct offline engines' misread glyphs (e/o, i/l) with an English word list"
    )
    ocr_language: Literal["en", "any"] = Field(
        "en", description="the language of the pages: offline engines read only its characters, and the "
        "correction of coherent text uses its language model (English is the only one so far); any: every "
        "character the engine knows, and only the word list's fixes of non-words",
    )
    line_confidence_model: Path | None = Field(
        None, description="the calibrated line-confidence model (JSON, `darkread eval calibrate`); unset = the shipped one"
    )
    ocr_timeout_s: float = Field(60.0, gt=0)
    ask_timeout_s: float = Field(90.0, gt=0, description="an ask (stitching + OCR) answers 503 after this long")
    ask_rate_per_min: float = Field(30.0, gt=0, description="asks and page.png per key per minute (sustained)")
    ask_burst: int = Field(10, ge=1, description="asks and page.png per key at once")

    google_base_url: str = "https://vision.googleapis.com"
    google_api_key: SecretStr | None = None
    google_bearer_token: SecretStr | None = None

    openai_base_url: str = "https://api.openai.com/v1"
    openai_api_key: SecretStr | None = None
    openai_model: str = "gpt-4o-mini"
    openai_prompt: str = OCR_PROMPT
    openai_token_param: Literal["max_tokens", "max_completion_tokens"] = "max_completion_tokens"
    openai_max_output_tokens: int = Field(1024, ge=1)
    openai_max_retries: int = Field(2, ge=0, description="retries after HTTP 429, honouring retry-after")

    # Spoken answers (ask with Accept: audio/wav): the offline espeak-ng engine.
    speech_engine: str = Field("espeak-ng", description="the espeak-ng executable (a name on PATH or a path)")
    speech_language: str = Field("en-us", pattern=VOICE_NAME_PATTERN, description="espeak-ng language, e.g. en-us, en-gb")
    speech_voice: str = Field(
        "f2", pattern=f"{VOICE_NAME_PATTERN}|^$", description="espeak-ng voice variant (f2: the most intelligible here); empty = the plain voice"
    )
    speech_rate_wpm: int = Field(140, ge=80, le=450, description="speaking rate in words per minute")
    speech_timeout_s: float = Field(20.0, gt=0, description="longest a single answer may take to synthesise")
    speech_part_words: int = Field(
        200, ge=10, le=2000, description="a longer answer is spoken in parts of at most this many words (?part=N)"
    )
    speech_max_seconds: float = Field(
        180.0, gt=0, le=3600, description="audio of one spoken part is cut after this long (bounds its memory)"
    )
    speech_threads: int = Field(2, ge=1, description="syntheses running at once (all keys); more wait their turn")
    speech_per_key: int = Field(2, ge=1, description="syntheses one key may have running or waiting at once; 429 beyond")

    def voice(self) -> Voice:
        return Voice(self.speech_language, self.speech_voice, self.speech_rate_wpm)

    @field_validator("allowed_origins", mode="before")
    @classmethod
    def _origin_list(cls, value: object) -> object:
        """``DARKREAD_ALLOWED_ORIGINS=https://a.example,https://b.example`` as well as a JSON list."""
        if isinstance(value, str):
            text = value.strip()
            value = json.loads(text) if text.startswith("[") else [part for part in text.split(",") if part.strip()]
        if isinstance(value, list | tuple):
            return [normalise_origin(str(item)) for item in value]
        return value

    @field_validator("api_key", mode="before")
    @classmethod
    def _empty_key_is_an_error(cls, value: object) -> object:
        """An empty key is a mistake (an unset variable in a compose file), not "no auth"."""
        if isinstance(value, str | SecretStr) and not str(getattr(value, "get_secret_value", lambda: value)()).strip():
            raise ValueError("DARKREAD_API_KEY / --api-key is empty; set a key or leave it unset")
        return value

    @field_validator("database_url", "google_api_key", "google_bearer_token", "openai_api_key", mode="before")
    @classmethod
    def _empty_is_unset(cls, value: object) -> object:
        """``DARKREAD_OPENAI_API_KEY=`` (empty) means no key, not the empty key."""
        return None if value in ("", None) else value

    @field_validator("database_url")
    @classmethod
    def _postgres_url(cls, value: SecretStr | None) -> SecretStr | None:
        if value is not None and not value.get_secret_value().startswith(("postgresql://", "postgres://")):
            raise ValueError("DARKREAD_DATABASE_URL must be a postgresql:// URL")
        return value

    def keys_path(self) -> Path:
        return self.keys_file or self.data_dir / "keys.json"

    def database_path(self) -> Path:
        return self.data_dir / "darkread.sqlite3"


@lru_cache
def get_settings() -> Settings:
    """The process-wide settings (tests pass their own ``Settings`` to ``create_app``)."""
    return Settings()

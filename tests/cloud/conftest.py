"""Cloud fixtures: a real uvicorn server on 127.0.0.1 (random free port) in a thread."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from darkread.cloud.app import create_app
from darkread.cloud.ocr.base import OcrLine, OcrResult
from darkread.cloud.server import serve_in_thread
from darkread.cloud.settings import Settings

API_KEY = "test-key-7f3a"


@dataclass
class RecordingOcr:
    """An OCR engine for route tests: reports what it was given (shape and ink count)."""

    name: str = "recording"
    images: list[np.ndarray] = field(default_factory=list)

    def read(self, image: np.ndarray) -> OcrResult:
        self.images.append(image.copy())
        ink = int((image == 0).sum())
        text = f"{image.shape[0]}x{image.shape[1]} ink={ink}"
        return OcrResult(text=text, lines=[OcrLine(text=text, box=(0, 0, image.shape[1], image.shape[0]), confidence=1.0)])

    def ready(self) -> bool:
        return True


@dataclass
class LiveServer:
    url: str  # http://127.0.0.1:PORT
    ws_url: str  # ws://127.0.0.1:PORT/v1/stream
    settings: Settings
    ocr: RecordingOcr
    app: object

    @property
    def context(self):  # the app's AppContext
        return self.app.state.context


@pytest.fixture
def run_server() -> Callable[..., AbstractContextManager[LiveServer]]:
    """``with run_server(settings[, ocr]) as live:`` a real uvicorn on 127.0.0.1, random port."""

    @contextmanager
    def run(settings: Settings, ocr: RecordingOcr | None = None) -> Iterator[LiveServer]:
        ocr = ocr or RecordingOcr()
        app = create_app(settings, ocr=ocr)
        with serve_in_thread(app, ws_max_size=settings.max_message_bytes + 65536) as running:
            yield LiveServer(running.url, running.ws_url, settings, ocr, app)

    return run


@pytest.fixture
def api_key() -> str:
    return API_KEY


@pytest.fixture
def make_settings(tmp_path: Path) -> Callable[..., Settings]:
    def make(**overrides: Any) -> Settings:
        # a question waits for every frame stored before it (a loaded CI host stitches slowly)
        values: dict[str, Any] = {
            "data_dir": tmp_path / "data", "api_key": API_KEY, "max_message_bytes": 65536, "ask_catch_up_s": 60.0,
            "ask_rate_per_min": 6000.0, "ask_burst": 100,  # wearers asking every few seconds (limits: test_ask_limits)
        }  # fmt: skip
        values.update(overrides)
        return Settings(_env_file=None, **values)

    return make


@pytest.fixture
def server(make_settings: Callable[..., Settings], run_server: Callable[..., AbstractContextManager[LiveServer]]) -> Iterator[LiveServer]:
    with run_server(make_settings()) as live:
        yield live

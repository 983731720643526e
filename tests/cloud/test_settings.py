"""Settings come from DARKREAD_* variables; secrets never show in reprs."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from darkread.cloud.settings import Settings


def test_environment_variables_are_read(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("DARKREAD_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("DARKREAD_API_KEY", "s3cret")
    monkeypatch.setenv("DARKREAD_OCR_BACKEND", "openai")
    monkeypatch.setenv("DARKREAD_OPENAI_TOKEN_PARAM", "max_tokens")
    settings = Settings(_env_file=None)
    assert settings.data_dir == tmp_path and settings.ocr_backend == "openai"
    assert settings.api_key is not None and settings.api_key.get_secret_value() == "s3cret"
    assert settings.openai_token_param == "max_tokens"
    assert "s3cret" not in repr(settings) and "s3cret" not in str(settings.model_dump())


def test_empty_key_is_an_error_not_no_key(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DARKREAD_API_KEY", "")
    with pytest.raises(ValidationError, match="empty"):
        Settings(_env_file=None)
    monkeypatch.setenv("DARKREAD_OPENAI_API_KEY", "")
    monkeypatch.delenv("DARKREAD_API_KEY")
    assert Settings(_env_file=None).openai_api_key is None


@pytest.mark.parametrize(("name", "value"), [("DARKREAD_OCR_BACKEND", "easyocr"), ("DARKREAD_MAX_MESSAGE_BYTES", "10")])
def test_invalid_values_are_refused(monkeypatch: pytest.MonkeyPatch, name: str, value: str) -> None:
    monkeypatch.setenv(name, value)
    with pytest.raises(ValidationError):
        Settings(_env_file=None)

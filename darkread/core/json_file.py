"""Reading a JSON file a user handed us: one line that says which file and what is wrong with it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def read_json_file(
    path: str | Path, what: str, *, error: type[Exception] = ValueError, missing: str = "",
    not_found: type[Exception] | None = None,
) -> Any:
    """The parsed document of ``path``; ``not_found`` (default ``error``) with ``<path>: <what> not
    found[ (missing)]``, or ``error`` with ``<path>: not a readable <what>: <reason>`` (``missing``:
    how to make one)."""
    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise (not_found or error)(f"{path}: {what} not found" + (f" ({missing})" if missing else "")) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise error(f"{path}: not a readable {what} (JSON): {exc}") from exc

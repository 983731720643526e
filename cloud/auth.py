"""Who may do what: API keys per device with scopes, stored hashed; loopback-only without keys.

A key is ``drk_<id>_<secret>``. The keys file (``<data dir>/keys.json``, mode 0600) keeps, per
key, its id, the device it belongs to, its scopes and the SHA-256 of the whole key, never the
key itself (keys are 256-bit random tokens, so a fast hash cannot be brute-forced). Scopes:

* ``stream``: open and stream sessions of its own device (``hello.device_id`` must be it);
* ``read``: list, read and ask about its own device's sessions;
* ``admin``: everything, every device, plus ``DELETE`` and ``/metrics``.

``DARKREAD_API_KEY`` is one admin key (for a single-user deployment). With no key at all the
service answers loopback clients only (a developer's own machine) and ``darkread cloud serve``
refuses to bind any other address unless ``--insecure`` says so.
"""

from __future__ import annotations

import hashlib
import ipaddress
import json
import logging
import os
import re
import secrets
import time
from collections.abc import Iterable, MutableMapping
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

from darkread.core.redact import RedactKeys

log = logging.getLogger(__name__)

KEY_PREFIX = "drk"
_KEY = re.compile(rf"^{KEY_PREFIX}_([0-9a-f]{{8}})_[A-Za-z0-9_-]{{20,}}$")


class Scope(StrEnum):
    STREAM = "stream"
    READ = "read"
    ADMIN = "admin"


def parse_scopes(text: str) -> frozenset[Scope]:
    """``"stream,read"`` -> the scopes; ValueError naming the valid ones otherwise."""
    names = [part.strip() for part in text.split(",") if part.strip()]
    valid = ", ".join(s.value for s in Scope)
    if not names:
        raise ValueError(f"--scope needs at least one of: {valid}")
    try:
        return frozenset(Scope(name) for name in names)
    except ValueError:
        raise ValueError(f"unknown scope in {text!r}; scopes are: {valid}") from None


@dataclass(frozen=True)
class Principal:
    """The caller a key stands for. ``device`` None: any device (admin keys)."""

    key_id: str
    device: str | None
    scopes: frozenset[Scope]

    def can(self, scope: Scope) -> bool:
        return Scope.ADMIN in self.scopes or scope in self.scopes

    def owns(self, device_id: str) -> bool:
        """May act on a session of ``device_id``."""
        return Scope.ADMIN in self.scopes or self.device is None or self.device == device_id


# DARKREAD_API_KEY beyond loopback: a key anyone could guess in a few tries is no key (device keys
# made by ``keys add`` are 32 random bytes).
MIN_API_KEY_CHARS = 16

ALL_SCOPES = frozenset(Scope)
LOOPBACK_DEVELOPER = Principal("loopback", None, ALL_SCOPES)  # no keys configured, local client
ENVIRONMENT_ADMIN = Principal("env", None, ALL_SCOPES)  # DARKREAD_API_KEY


def key_hash(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()


def is_loopback(host: str | None) -> bool:
    """``127.0.0.0/8``, ``::1`` and ``localhost``; anything else (or unknown) is not."""
    if not host:
        return False
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class KeyRecord:
    key_id: str
    device: str
    scopes: frozenset[Scope]
    sha256: str
    created_s: float

    def to_json(self) -> dict[str, object]:
        return {"id": self.key_id, "device": self.device, "scopes": sorted(s.value for s in self.scopes),
                "sha256": self.sha256, "created_s": self.created_s}

    @classmethod
    def from_json(cls, item: dict[str, Any]) -> KeyRecord:
        return cls(str(item["id"]), str(item["device"]), parse_scopes(",".join(item["scopes"])),
                   str(item["sha256"]), float(item.get("created_s", 0.0)))


class KeyRing:
    """The keys file; re-read when it changes on disk, so ``keys add`` needs no restart."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._records: dict[str, KeyRecord] = {}
        self._stamp: tuple[int, int] | None = None

    def records(self) -> list[KeyRecord]:
        self._refresh()
        return sorted(self._records.values(), key=lambda r: r.created_s)

    def __bool__(self) -> bool:
        return bool(self.records())

    def authenticate(self, candidate: str | None) -> Principal | None:
        if not candidate or not (match := _KEY.match(candidate)):
            return None
        self._refresh()
        record = self._records.get(match.group(1))
        if record is None or not secrets.compare_digest(record.sha256, key_hash(candidate)):
            return None
        return Principal(record.key_id, record.device, record.scopes)

    def add(self, device: str, scopes: Iterable[Scope]) -> str:
        """A new key for ``device``; returns the key (the only time it exists in clear)."""
        self._refresh()
        key_id = secrets.token_hex(4)
        while key_id in self._records:
            key_id = secrets.token_hex(4)
        key = f"{KEY_PREFIX}_{key_id}_{secrets.token_urlsafe(32)}"
        self._records[key_id] = KeyRecord(key_id, device, frozenset(scopes), key_hash(key), time.time())
        self._write()
        return key

    def revoke(self, key_id: str) -> bool:
        self._refresh()
        if self._records.pop(key_id, None) is None:
            return False
        self._write()
        return True

    def _refresh(self) -> None:
        try:
            stat = self.path.stat()
        except FileNotFoundError:
            self._records, self._stamp = {}, None
            return
        stamp = (stat.st_mtime_ns, stat.st_size)
        if stamp == self._stamp:
            return
        try:
            items = json.loads(self.path.read_text())["keys"]
            self._records = {r.key_id: r for r in map(KeyRecord.from_json, items)}
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"{self.path}: not a darkread keys file ({exc})") from None
        self._stamp = stamp

    def _write(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(".tmp")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as handle:
            json.dump({"keys": [r.to_json() for r in self._records.values()]}, handle, indent=1)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, self.path)
        self._stamp = None


def install_log_redaction() -> None:
    """Uvicorn logs websocket paths with their query string (``?key=``): redact its loggers."""
    for name in ("uvicorn", "uvicorn.error", "uvicorn.access", "websockets", "websockets.server"):
        logger = logging.getLogger(name)
        if not any(isinstance(f, RedactKeys) for f in logger.filters):
            logger.addFilter(RedactKeys())


UNAUTHORIZED = "missing or wrong API key (send it in the X-API-Key header)"


def principal_of(scope: MutableMapping[str, Any]) -> Principal | None:
    """The caller the request guard (``guard.py``) authenticated for this request (None: a route without a key)."""
    principal = scope.get("state", {}).get("principal")
    return principal if isinstance(principal, Principal) else None

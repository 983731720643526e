"""How the edge's per-event loops are compiled: numba, cached on disk where numba can write.

numba keeps compiled machine code beside the module or in the user's cache directory. Under the
edge's systemd unit neither may be writable (``ProtectSystem=strict``, ``ProtectHome=yes``); the
unit gives numba ``NUMBA_CACHE_DIR`` in its own cache directory, and where no such place exists
numba refuses ``cache=True`` outright (a RuntimeError when the module is imported). Then the loops
are compiled without a cache: about a second at each start, spent in the warm-up before READY.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numba as nb

log = logging.getLogger(__name__)


def compiled(function: Callable[..., Any]) -> Any:
    """``numba.njit(nogil=True)`` of ``function``, with numba's on-disk cache when it has one."""
    try:
        return nb.njit(cache=True, nogil=True)(function)
    except RuntimeError as exc:  # "cannot cache function ...: no locator available"
        log.info("%s: compiled at every start (%s)", function.__qualname__, exc)
        return nb.njit(nogil=True)(function)

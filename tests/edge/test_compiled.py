"""The edge's compiled loops work where numba can keep no cache (a read-only install under systemd)."""

from __future__ import annotations

import numpy as np

from darkread.edge.compiled import compiled


def test_a_loop_numba_cannot_cache_is_compiled_without_a_cache() -> None:
    # a function with no source file on disk: numba finds no place for its cache, as under
    # ProtectSystem=strict and ProtectHome=yes, and refuses cache=True
    namespace: dict[str, object] = {}
    exec(compile("def total(a):\n    s = 0.0\n    for v in a:\n        s += v\n    return s\n", "<no file>", "exec"), namespace)
    total = compiled(namespace["total"])
    assert total(np.arange(5.0)) == 10.0
    assert type(total._cache).__name__ == "NullCache"  # compiled at every start, nothing kept on disk


def test_a_loop_in_a_module_is_cached() -> None:
    from darkread.edge.binning import voters

    assert type(voters._cache).__name__ == "FunctionCache"  # numba keeps its machine code on disk

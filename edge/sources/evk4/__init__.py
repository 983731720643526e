"""Live Prophesee EVK4 / EVK3 HD (IMX636) over USB with pyusb, and a fake board for tests.

Importing the package is cheap and needs no USB stack (the CLI imports ``evk4.cli``);
``Evk4Camera`` loads pyusb on first use.
"""

from __future__ import annotations

from typing import Any

__all__ = ["Evk4Camera"]


def __getattr__(name: str) -> Any:
    if name == "Evk4Camera":
        from darkread.edge.sources.evk4.camera import Evk4Camera  # lazy: importing the package needs no USB stack

        return Evk4Camera
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

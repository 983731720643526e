"""Live Prophesee EVK4 / EVK3 HD (IMX636) over USB with pyusb, and a fake board for tests."""

from darkread.edge.sources.evk4.camera import Evk4Camera

__all__ = ["Evk4Camera"]

"""VMC protocol (OSC over UDP) receiver plugins: vmc.suit and vmc.glove."""

from teleprev_devices.vmc.plugins import VmcGlove, VmcSuit

__all__ = ["VmcGlove", "VmcSuit"]

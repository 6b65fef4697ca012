"""WebXR hand tracking (an XR headset's browser) as a glove and a suit: webxr.glove and webxr.suit."""

from teleprev_devices.webxr.plugins import WebXrGlove, WebXrSuit

__all__ = ["WebXrGlove", "WebXrSuit"]

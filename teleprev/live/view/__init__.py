"""The live Foxglove view of a session (a WebSocket server on loopback) and its layout."""

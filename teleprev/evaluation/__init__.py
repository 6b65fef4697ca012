"""Replay and offline evaluation of recorded sessions."""

"""Playback of a recorded session or a dataset episode to a robot (sim or real), within its limits."""

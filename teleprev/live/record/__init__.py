"""A recording: a live session's wiring (devices, pipeline, loop, recorder), the operator's keys, the
keyboard and scripted runners, timed episodes' schedule and cues, and the sensors' frames on /tf."""

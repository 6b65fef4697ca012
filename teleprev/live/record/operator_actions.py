"""The operator's keys and what each does to a recording; the same actions by name, for controls other than
the keyboard (the XR page): each is the key the terminal preview binds to it, pressed on the recording,
so that a pinch in the headset does exactly what the key does, in an interactive run and in timed episodes
alike. And the status such a control shows the operator."""

from __future__ import annotations


def handle_key(recording, key: str, quit_flag: list) -> None:
    """What a key does to a recording (a LiveSession); q and Esc also append to `quit_flag`."""
    loop = recording.loop
    if key == " ":
        if loop.snapshot.mode == "execute":
            loop.to_preview()
        else:
            loop.engage()
    elif key == "x":  # e-stop: teleprev sends nothing more at once; the controller stops the robot itself
        loop.estop()
    elif key == "s":
        loop.start_episode(recording.task)
    elif key == "e":
        loop.stop_episode()
    elif key == "n":
        loop.to_preview()
        loop.start_episode(recording.task)
    elif key == "d":
        loop.discard_episode()
    elif key == "a":  # the running (or last) episode discarded, and recorded again from now
        loop.to_preview()
        loop.discard_episode()
        loop.start_episode(recording.task)
    elif key in ("y", "f"):
        loop.mark_outcome(key == "y")
    elif key == "r":
        loop.note("ready")
    elif key in ("q", "\x1b"):
        loop.to_preview()
        quit_flag.append(True)


ACTION_KEYS = {
    "toggle_mode": " ", "estop": "x", "start": "s", "stop": "e", "next": "n", "discard": "d", "again": "a",
    "success": "y", "failure": "f", "ready": "r",
}


def operator_status(snapshot) -> dict:
    """What the operator is shown away from the terminal: mode, episode, and the hand links the Corrector
    changed on the last step."""
    step = snapshot.step
    report = step.report if step is not None else {}
    return {
        "recording": True,
        "mode": snapshot.mode,
        "episode": snapshot.episode,
        "episode_active": snapshot.episode_active,
        "task": snapshot.task,
        "corrector": report.get("corrector", ""),
        "corrected_links": sorted(report.get("colliding_links", ())),
        "message": snapshot.message,
        "fault": snapshot.fault,
        "commands_sent": snapshot.commands_sent,
    }

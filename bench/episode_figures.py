"""Timed episodes: how close the recorded boundaries come to the plan, and whether the robot rests by
each episode's end and stays still through the resets.

    python bench/episode_figures.py [--json] [--quick]

One unattended run of 4 episodes of 1.5 s with 1 s resets (engaging 0.3 s into each) on the default sim
rig, headless, through run_timed as `teleprev record --episodes 4 --episode-time 1.5 --reset-time 1
--engage-after 0.3` does, read back from its file:

    episode_timing_err_ms_max   largest |recorded boundary - requested time| over every episode start and
                                stop (the episode events' stamps), the requested times planned from the
                                instant the bench started the run
    episode_event_lag_ms_max    largest (log time - stamp) of those events: how late the session loop got
                                round to recording them (the stamps do not depend on it)
    preview_lag_ms_max          largest delay of the switch to preview behind its planned instant (the
                                episode's end minus preview_before_end_s): eats into the braking margin
    rest_before_end_ms_min      smallest time from the last arm command (at rest) to its episode's end
    reset_commands              commands stamped inside a reset (should be 0)

JSON keys:
    episode_timing_err_ms_max  float
    episode_event_lag_ms_max   float
    preview_lag_ms_max         float
    rest_before_end_ms_min     float
    preview_before_end_ms      float
    engaged_episodes           int
    episodes                   int
    reset_commands             int
    steal_ms                   float
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402  (sets one-thread environment before numpy loads)

PLAN = dict(episodes=4, episode_s=1.5, reset_s=1.0, engage_after_s=0.3)


def measure(folder: Path, episodes: int = PLAN["episodes"]) -> dict:
    from teleprev import topics
    from teleprev.live.record.cues import Cues
    from teleprev.live.record.run import run_timed
    from teleprev.live.record.schedule import EpisodeTimes
    from teleprev.live.record.session import LiveSession, RecordOptions
    from teleprev.session.reader import SessionReader

    plan = EpisodeTimes(**{**PLAN, "episodes": episodes}).check()
    path = Path(folder) / "timed.mcap"
    rec = LiveSession(RecordOptions(out=path, episode_plan=plan))
    rec.start()
    try:
        if rec.wait_connected():
            raise RuntimeError("the sim rig's devices did not connect")
        t0 = rec.clock.now_ns()
        run_timed(rec, plan, cues=Cues(None, None))
    finally:
        rec.stop()
    lead_ns = round(rec.preview_lead_s * 1e9)
    with SessionReader(path) as reader:
        found = reader.episodes()
        events = [m for m in reader.messages([topics.EPISODE]) if m.payload.data["event"] in ("start", "stop")]
        previews = [m.log_time_ns for m in reader.messages([topics.MODE]) if m.payload.data["mode"] == "preview"]
        arm = [m.payload for m in reader.messages([topics.COMMAND_ARM])] if topics.COMMAND_ARM in reader.topics else []
    period_ns = round((plan.episode_s + plan.reset_s) * 1e9)
    episode_ns = round(plan.episode_s * 1e9)
    errors, lags, rests = [], [], []
    for k, e in enumerate(found):
        start, stop = t0 + k * period_ns, t0 + k * period_ns + episode_ns
        errors += [abs(e.start_ns - start), abs(e.stop_ns - stop)]
        planned_preview = stop - lead_ns
        after = [t for t in previews if t >= planned_preview - 50_000_000]
        if after and after[0] <= stop + 1_000_000_000:
            lags.append(after[0] - planned_preview)
        inside = [c.stamp_ns for c in arm if e.start_ns <= c.stamp_ns <= e.stop_ns]
        if inside:
            rests.append(e.stop_ns - inside[-1])
    resets = [(a.stop_ns, b.start_ns) for a, b in zip(found, found[1:])]
    in_resets = sum(1 for c in arm if any(a < c.stamp_ns < b for a, b in resets))
    return {
        "episode_timing_err_ms_max": max(errors) / 1e6,
        "episode_event_lag_ms_max": max(m.log_time_ns - m.payload.stamp_ns for m in events) / 1e6,
        "preview_lag_ms_max": max(lags) / 1e6 if lags else float("nan"),
        "rest_before_end_ms_min": min(rests) / 1e6 if rests else float("nan"),
        "preview_before_end_ms": lead_ns / 1e6,
        "engaged_episodes": len(rests),
        "episodes": len(found),
        "reset_commands": in_resets,
    }


def main() -> None:
    args = common.parser(__doc__.splitlines()[0]).parse_args()
    steal = common.steal_ms()
    with tempfile.TemporaryDirectory(prefix="teleprev-episodes-") as tmp:
        figures = measure(Path(tmp), 2 if args.quick else PLAN["episodes"])
    after = common.steal_ms()
    if steal is not None and after is not None:
        figures["steal_ms"] = round(after - steal, 1)
    targets = {"episode_timing_err_ms_max": "<= 50", "rest_before_end_ms_min": "> 0", "reset_commands": "0",
               "episodes": str(2 if args.quick else PLAN["episodes"])}
    common.report("teleprev timed episodes (machine shared: lags are noisy)", figures, targets, args.json)


if __name__ == "__main__":
    main()

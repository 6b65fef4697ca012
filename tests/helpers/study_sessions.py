"""User-study sessions written from a script: real MCAP files holding only metadata and events."""

from teleprev import topics
from teleprev.messages import Event, Logged
from teleprev.session.writer import McapSessionWriter
from teleprev.study import survey

S = 10**9


def scripted(path, condition, end_effector, episodes=(), practice_s=None, participant="p1", task="pick_place",
             practice_start=True, answers=None):
    """episodes: (duration_s, outcome or None, discarded[, stopped]); practice_s: the ready key this long after
    the practice start (None with practice_s=-1: a practice session without ready); answers: stored as its survey."""
    practice = practice_s is not None
    meta = {"session": {"participant": participant, "condition": condition, "end_effector": end_effector, "task": task,
                        "practice": "true" if practice else "false"},
            "study": {"survey_sidecar": path.with_suffix(".survey.json").name}}
    t = 1000 * S

    with McapSessionWriter(path, meta) as w:
        def event(topic, schema, data):
            w.write(Logged(topic, t, Event(t, schema, data)))

        def episode(k, kind, **extra):
            event(topics.EPISODE, "teleprev.EpisodeEvent", {"event": kind, "episode": k, "task": task, **extra})

        event(topics.MODE, "teleprev.ModeSwitch", {"mode": "preview", "reason": "start"})  # the session's first message
        if practice:
            t += 3 * S
            if practice_start:
                event(topics.OPERATOR, "teleprev.OperatorEvent", {"event": "practice_start"})
            if practice_s >= 0:
                t += int(practice_s * S)
                event(topics.OPERATOR, "teleprev.OperatorEvent", {"event": "ready"})
        for k, (duration, outcome, discarded, *stopped) in enumerate(episodes):
            t += 2 * S
            episode(k, "start")
            t += int(duration * S)
            if stopped != [False]:
                episode(k, "stop")
            if discarded:
                episode(k, "discard")
            if outcome:
                t += S // 2  # marked after the stop: not part of the execution time
                episode(k, "outcome", outcome=outcome)
    if answers is not None:
        survey.store(survey.target(path), dict(zip(survey.KEYS, answers)))
    return path

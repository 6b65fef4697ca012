"""`teleprev eval --plots` figures: how long the episode plots take per session.

    python bench/plots.py [--json] [--quick]

Re-runs the fixture sessions (tests/fixtures/sim_v1.mcap and sim_v2.mcap: two episodes each, the
Corrector changing most steps) once, then times plot_episodes on each:

    plot_s_per_session_max   the slowest session's plots (target: about 1 s)
    plot_s_per_episode_p50   median over the episodes

--quick: sim_v1.mcap only.

JSON keys:
    plot_s_per_session_max  float
    plot_s_per_episode_p50  float
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = [ROOT / "tests" / "fixtures" / name for name in ("sim_v1.mcap", "sim_v2.mcap")]


def main() -> None:
    args = common.parser(__doc__.splitlines()[0]).parse_args()
    from teleprev.evaluation.plots import plot_episodes
    from teleprev.evaluation.reproduce import rerun_session

    reruns = [rerun_session(path) for path in (FIXTURES[:1] if args.quick else FIXTURES)]
    plot_episodes(reruns[0], tempfile.mkdtemp())  # matplotlib's first figure (fonts, caches) is not a session's
    per_session, per_episode = {}, []
    with tempfile.TemporaryDirectory() as out:
        for r in reruns:
            t = time.perf_counter()
            n = len(plot_episodes(r, out))
            per_session[r.session.name] = time.perf_counter() - t
            per_episode += [per_session[r.session.name] / max(n, 1)] * n
    figures = {f"plot_s_{name}": s for name, s in per_session.items()}
    figures["plot_s_per_session_max"] = max(per_session.values())
    figures["plot_s_per_episode_p50"] = common.percentile(per_episode, 50)
    common.report("eval --plots", figures, {"plot_s_per_session_max": "about 1"}, args.json)


if __name__ == "__main__":
    main()

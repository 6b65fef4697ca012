"""Export recorded sessions to LeRobot datasets (v3.0), written with lerobot's own LeRobotDataset API.

    recipe.py     which recorded streams become which features (TOML in datasets/recipes/), resolved by role
    streams.py    one episode's streams read from a session into arrays (the camera frames stay on disk)
    timeline.py   the frame times and which sample of each stream every frame uses (no future for
                  observations), gaps, splits and the alignment error
    video.py      video settings (codec, quality, threads): no lerobot import
    lerobot_video.py  the streaming encoder the dataset writes its videos with (imports lerobot; loaded lazily)
    dataset.py    the LeRobotDataset being written: staged in a temporary folder, moved into place
    session.py    one session through the timeline into the dataset, episode by episode
    parallel.py   several sessions in worker processes, merged with lerobot's aggregation
    run.py        an export from start to summary: checks, staging, progress, report
    report.py     what an export did: episodes, frames, splits, alignment error, size
    selection.py  which episodes: outcome marks, task, participant, condition, a held-out split
    episode_meta.py  where each episode came from, as extra columns of lerobot's meta/episodes
    actions.py    a dataset's `action` column read back without lerobot (audit, replay)
    synthetic.py  sessions with exactly known content, for tests, benchmarks and trying the exporter

lerobot (and torch) are imported only inside the functions that write or read datasets.
"""

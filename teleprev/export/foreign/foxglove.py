"""Foxglove-schema MCAP files that teleprev did not record: foxglove.JointStates, CompressedImage,
PoseInFrame and FrameTransforms in protobuf (what the Foxglove SDK and `mcap` writers produce), read by
teleprev's own session reader, with episodes cut as the import recipe says instead of from teleprev's
episode events, and joint streams given with the recipe's joints in its order (as the ROS path does)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from teleprev.errors import SessionError
from teleprev.export.foreign.config import ImportRecipe
from teleprev.export.foreign.episodes import cut_episodes
from teleprev.export.recipe import JOINTS
from teleprev.messages import JointSample, Logged
from teleprev.session.reader import Episode, SessionReader


class FoxgloveReader:
    def __init__(self, path: str | Path, recipe: ImportRecipe):
        self._session = SessionReader(path, any_mcap=True)
        self.path = self._session.path
        self.recipe = recipe
        ours = {"rig": {"robot": recipe.robot_type}, "session": {"task": recipe.section.task},
                "import": {"source": str(self.path), "format": "foxglove"}}
        try:  # a damaged index or metadata record raises here: the file is closed before the error goes up
            self.topics = self._session.topics
            self.metadata = {**self._session.metadata, **ours}
        except BaseException:
            self._session.close()
            raise
        self.start_ns = self._session.start_ns
        self.end_ns = self._session.end_ns
        self._names: dict[str, tuple[str, ...]] = {}
        self._index: dict[tuple, np.ndarray] = {}  # (topic, recorded names) -> where the given joints are

    def messages(self, topics=None, start_ns=None, end_ns=None) -> Iterator[Logged]:
        for msg in self._session.messages(topics, start_ns, end_ns):
            if isinstance(msg.payload, JointSample) and self.recipe.joint_order(msg.topic):
                msg = self._selected(msg)
            yield msg

    def joint_names(self, topic: str) -> tuple[str, ...]:
        """The joints a JointStates stream is given with (ImportRecipe.select_joints on its first message)."""
        if topic not in self._names:
            first = next(iter(self._session.messages([topic])), None)
            if first is None or not isinstance(first.payload, JointSample):
                raise SessionError(f"{topic} has no joint states", str(self.path))
            self._names[topic] = self.recipe.select_joints(topic, tuple(first.payload.names), str(self.path))
        return self._names[topic]

    def _selected(self, msg: Logged) -> Logged:
        p, names = msg.payload, self.joint_names(msg.topic)
        index = self._index.get((msg.topic, p.names))
        if index is None:
            where = {n: k for k, n in enumerate(p.names)}
            missing = [n for n in names if n not in where]
            if missing:
                raise SessionError(f"{msg.topic} at log time {msg.log_time_ns}: no joints {missing} in this message",
                                   str(self.path))
            index = self._index[(msg.topic, p.names)] = np.array([where[n] for n in names])
        return Logged(msg.topic, msg.log_time_ns, JointSample(p.stamp_ns, names, np.asarray(p.positions)[index]))

    def episodes(self) -> list[Episode]:
        joints = [t for t, info in self.topics.items() if info.schema == JOINTS]
        return cut_episodes(self, self.recipe.section, joints)

    def close(self) -> None:
        self._session.close()

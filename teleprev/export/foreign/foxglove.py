"""Foxglove-schema MCAP files that teleprev did not record: foxglove.JointStates, CompressedImage,
PoseInFrame and FrameTransforms in protobuf (what the Foxglove SDK and `mcap` writers produce), read by
teleprev's own session reader, with episodes cut as the import recipe says instead of from teleprev's
episode events."""

from __future__ import annotations

from pathlib import Path

from teleprev.export.foreign.config import ImportRecipe
from teleprev.export.foreign.episodes import cut_episodes
from teleprev.export.recipe import JOINTS
from teleprev.session.reader import Episode, SessionReader


class FoxgloveReader:
    def __init__(self, path: str | Path, recipe: ImportRecipe):
        self._session = SessionReader(path)
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

    def messages(self, topics=None, start_ns=None, end_ns=None):
        return self._session.messages(topics, start_ns, end_ns)

    def episodes(self) -> list[Episode]:
        joints = [t for t, info in self.topics.items() if info.schema == JOINTS]
        return cut_episodes(self, self.recipe.section, joints)

    def close(self) -> None:
        self._session.close()

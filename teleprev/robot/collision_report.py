"""What a self-collision check reports for one configuration (both checkers return it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CollisionReport:
    labels: np.ndarray  # bool per checked link (the checker's link_names)
    pairs: tuple[tuple[str, str], ...]  # colliding link pairs

    @property
    def colliding(self) -> bool:
        return bool(self.pairs)

    def colliding_links(self, link_names) -> list[str]:
        return [n for n, hit in zip(link_names, self.labels) if hit]

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


def link_labels(pairs: np.ndarray, pair_links: np.ndarray, n_links: int) -> np.ndarray:
    """(N, n_links) bool: a link is labelled colliding when any pair it belongs to collides.
    `pairs` is (N, P) bool over the checked pairs, `pair_links` (P, 2) their link indices."""
    touches = np.zeros((len(pair_links), n_links), dtype=np.int32)  # pair -> its two links
    for side in (0, 1):
        touches[np.arange(len(pair_links)), pair_links[:, side]] = 1
    return (np.asarray(pairs, dtype=np.int32) @ touches) > 0

"""A foxglove.JointStates topic gathered as columns (stamps and positions) instead of messages."""

from __future__ import annotations

import numpy as np


class JointTable:
    """A foxglove.JointStates topic read by SessionReader.messages(tables=...): each message's stamp_ns
    and positions, in the order messages() would have yielded the messages."""

    __slots__ = ("stamp_ns", "positions")

    def __init__(self) -> None:
        self.stamp_ns: list[int] = []
        self.positions: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self.stamp_ns)

    def append(self, stamp_ns: int, positions: np.ndarray) -> None:
        self.stamp_ns.append(stamp_ns)
        self.positions.append(positions)

    def extend_in_order(self, stamps: list[int], positions: list[np.ndarray], indices: list[int]) -> None:
        """Append messages decoded in file order, taking them in `indices` order."""
        if indices == list(range(len(stamps))):
            self.stamp_ns.extend(stamps)
            self.positions.extend(positions)
        else:
            self.stamp_ns.extend([stamps[k] for k in indices])
            self.positions.extend([positions[k] for k in indices])

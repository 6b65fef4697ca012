"""What one SessionReader.messages() call reads (ReadRequest), and the wanted messages of one or more
chunks as bytes per channel with their log time order (LocatedMessages, MessageOrder)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from teleprev.session.joint_table import JointTable


@dataclass(frozen=True, slots=True)
class ReadRequest:
    """What one messages() call reads: decoders and topic names by channel, the log time window, the
    wanted channels and the tabled ones."""

    decoders: dict
    names: dict[int, str]
    lo: int
    hi: int
    wanted: frozenset
    tabled: dict[int, JointTable]

    def untabled(self) -> ReadRequest:
        return ReadRequest(self.decoders, self.names, self.lo, self.hi, self.wanted, {})


class MessageOrder:
    """Wanted messages of one or more chunks in log time order (file order for equal times): per message its
    channel, its index among that channel's messages in file order, and its log time (int64 arrays)."""

    __slots__ = ("channels", "indices_", "times")

    def __init__(self, channels: np.ndarray, indices: np.ndarray, times: np.ndarray):
        self.channels, self.indices_, self.times = channels, indices, times

    @classmethod
    def empty(cls) -> MessageOrder:
        none = np.zeros(0, dtype=np.int64)
        return cls(none, none, none)

    @classmethod
    def of(cls, entries: list[tuple[int, int, int]]) -> MessageOrder:
        if not entries:
            return cls.empty()
        channels, indices, times = zip(*entries)
        try:
            log_times = np.array(times, dtype=np.int64)
        except OverflowError:  # log times past int64 (year 2262): kept as Python integers
            log_times = np.array(times, dtype=object)
        return cls(np.array(channels, dtype=np.int64), np.array(indices, dtype=np.int64), log_times)

    def after(self, counts: dict[int, int]) -> MessageOrder:
        """This order with each channel's indices moved past `counts[channel]` earlier messages."""
        if not any(counts.values()):
            return self
        shift = np.zeros(max(counts) + 1, dtype=np.int64)
        shift[list(counts)] = list(counts.values())
        return MessageOrder(self.channels, self.indices_ + shift[self.channels], self.times)

    @classmethod
    def concat(cls, orders: list[MessageOrder]) -> MessageOrder:
        return cls(*(np.concatenate(column) for column in zip(*((o.channels, o.indices_, o.times) for o in orders))))

    def entries(self, exclude=()) -> Iterator[tuple[int, int, int]]:
        """(channel, index, log time) in order, leaving out the channels in `exclude`."""
        channels, indices, times = self.channels, self.indices_, self.times
        if exclude:
            keep = ~np.isin(channels, list(exclude))
            channels, indices, times = channels[keep], indices[keep], times[keep]
        return zip(channels.tolist(), indices.tolist(), times.tolist())

    def indices(self, channel: int) -> list[int]:
        """The channel's messages (their indices in file order) in log time order."""
        return self.indices_[self.channels == channel].tolist()

    def times_by_index(self, channel: int) -> list[int]:
        """The log times of the channel's messages in file order."""
        mine = self.channels == channel
        out = np.empty(int(mine.sum()), dtype=self.times.dtype)
        out[self.indices_[mine]] = self.times[mine]
        return out.tolist()


@dataclass(frozen=True, slots=True)
class LocatedMessages:
    """Wanted messages of one or more chunks: per channel their bytes in file order, and their order."""

    per_channel: dict[int, list[bytes]]
    order: MessageOrder

    @classmethod
    def join(cls, parts: list[LocatedMessages]) -> LocatedMessages:
        """Chunks that follow each other in time, as one: each channel's messages in chunk order."""
        if not parts:
            return cls({}, MessageOrder.empty())
        if len(parts) == 1:
            return parts[0]
        per_channel: dict[int, list[bytes]] = {}
        orders = []
        for part in parts:
            orders.append(part.order.after({ch: len(per_channel.get(ch, ())) for ch in part.per_channel}))
            for ch, datas in part.per_channel.items():
                per_channel.setdefault(ch, []).extend(datas)
        return cls(per_channel, MessageOrder.concat(orders))

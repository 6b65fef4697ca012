"""What one VMC (OSC) datagram means: the bones it updates, stamped on the session clock, or why it was skipped.

A datagram is one frame (senders put a frame in one bundle). The decoder keeps the latest transform of
every bone (a sender may split the skeleton over several bundles), and makes a Frame of each datagram that
updated a bone: what it updated plus the whole skeleton as known so far. Garbage never stops it: datagrams
that do not parse, VMC messages with wrong arguments, unknown bone names and non-finite numbers are
counted and skipped, and so are out-of-range values (a sender time or position no clock or room can
have), rotations that are not unit quaternions, datagrams from senders the allow list leaves out, and
anything else a datagram makes the parser raise. /VMC/Ext/T (sender time, seconds) stamps the frame
through ClockSync; without it the receive time does. A stamp ClockSync rejects as an outlier is counted
too (`clock_outliers`), so that the runner records it as an event.
"""

from __future__ import annotations

import ipaddress
import logging
import math
import socket
import statistics
import struct
import sys
import threading
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pythonosc
from pythonosc.osc_packet import OscPacket

from teleprev.devices import ClockSync
from teleprev_devices.vmc.unity import KNOWN_BONES

MAX_DATAGRAM = 65535
# Linux reports the datagrams its receive buffer had no room for (a running total) with each datagram
# received once this option is on (socket(7)); Python does not name the constant.
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40 if sys.platform.startswith("linux") else None)
ANCILLARY = socket.CMSG_SPACE(4)
_PERIOD_WINDOW = 32  # sender-time steps the sender's frame period is the median of
_PERIOD_MIN_STEPS = 8  # steps seen before gaps in the sender time are counted as lost frames
_RESYNC_NS = 1_000_000_000  # sender time going back this much: the sender restarted, start ClockSync over
MAX_SENDER_TIME_S = 1e10  # |/VMC/Ext/T| beyond this (317 years) is no clock
MAX_POSITION_M = 1000.0  # a bone or root further than this from the origin is no motion capture
UNIT_TOLERANCE = 1e-2  # |q| may differ from 1 by this much (float32 senders round); beyond it: not a rotation

ROOT = "/VMC/Ext/Root/Pos"
BONE = "/VMC/Ext/Bone/Pos"
TIME = "/VMC/Ext/T"


@dataclass(frozen=True, slots=True)
class BonePose:
    position: np.ndarray  # (3,) Unity coordinates, metres
    rotation: np.ndarray  # (4,) x y z w, Unity coordinates


@dataclass(frozen=True, slots=True)
class Frame:
    receive_ns: int
    stamp_ns: int  # acquisition time on the session clock
    updated: frozenset[str]  # bones this datagram carried ("" for the root)
    bones: dict[str, BonePose]  # every bone received so far (latest values); the root under ""


@dataclass
class Counters:
    datagrams: int = 0
    frames: int = 0
    malformed_packets: int = 0  # not OSC at all
    malformed_messages: int = 0  # a VMC address with the wrong arguments
    unknown_bones: int = 0
    non_finite: int = 0
    out_of_range: int = 0  # a sender time or a position beyond any real one
    non_unit_rotations: int = 0  # a quaternion whose norm is not 1
    failed_packets: int = 0  # datagrams whose handling raised anything else (counted, skipped)
    disallowed_senders: int = 0  # datagrams from an address the allow list leaves out
    # Lost before they were read ("lost_" counters: input that never arrived, not input refused):
    lost_socket_overruns: int = 0  # datagrams the kernel dropped, the receive buffer being full (Linux)
    lost_sequence_gaps: int = 0  # frames missing from /VMC/Ext/T's steps (the network, or the buffer)
    clock_outliers: int = 0  # sender times ClockSync rejected (mapped with its current offset)

    def errors(self) -> dict[str, int]:
        return {"malformed_packets": self.malformed_packets, "malformed_messages": self.malformed_messages,
                "unknown_bones": self.unknown_bones, "non_finite": self.non_finite, "out_of_range": self.out_of_range,
                "non_unit_rotations": self.non_unit_rotations, "failed_packets": self.failed_packets,
                "clock_outliers": self.clock_outliers, "disallowed_senders": self.disallowed_senders,
                "lost_socket_overruns": self.lost_socket_overruns, "lost_sequence_gaps": self.lost_sequence_gaps}



class VmcDecoder:
    """The receiving side's state between datagrams: the skeleton so far, the sender's clock, the counters."""

    def __init__(self, allow: tuple[str, ...] = ()):
        """`allow`: the sender addresses or networks ("192.168.1.7", "10.0.0.0/24") accepted; empty: any."""
        self.counters = Counters()
        self._allowed = tuple(ipaddress.IPv4Network(a, strict=False) for a in allow)
        self._bones: dict[str, BonePose] = {}
        self._sync = ClockSync()
        self._outliers_before = 0  # clock outliers of the ClockSyncs replaced after a sender restart
        self._last_device_ns: int | None = None
        self._steps: deque[int] = deque(maxlen=_PERIOD_WINDOW)  # recent positive sender-time steps
        self._outliers_between = 0  # frames with a rejected sender time since the last accepted one

    def datagram(self, data: bytes, ancillary: list, sender: tuple, receive_ns: int) -> Frame | None:
        """One datagram as recvmsg returned it (asked for ANCILLARY bytes of ancillary data): its Frame, or
        None (counted: whatever a datagram does to the parser, the next one is read)."""
        for level, kind, value in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(value) >= 4:
                total = struct.unpack("=I", value[:4])[0]  # dropped since the socket opened
                self.counters.lost_socket_overruns = max(self.counters.lost_socket_overruns, total)
        if self._allowed and not any(ipaddress.IPv4Address(sender[0]) in net for net in self._allowed):
            self.counters.disallowed_senders += 1
            return None
        try:
            return self.parse(data, receive_ns)
        except Exception:
            self.counters.failed_packets += 1
            return None

    def parse(self, data: bytes, receive_ns: int) -> Frame | None:
        """Apply one datagram; a Frame if it carried any bone (None for garbage or other messages)."""
        c = self.counters
        c.datagrams += 1
        warned = _OSC_WARNINGS.count()
        try:
            messages = [m.message for m in OscPacket(data).messages]
        except Exception:  # python-osc raises ParseError, and on some garbage IndexError/struct errors
            c.malformed_packets += 1
            return None
        c.malformed_messages += _OSC_WARNINGS.count() - warned  # elements python-osc skipped
        updated: dict[str, BonePose] = {}
        device_ns = None
        bad_time = False  # a frame whose sender time is unusable is skipped whole: no stamp can be trusted
        for msg in messages:
            address, params = msg.address, msg.params
            if address in (ROOT, BONE):
                pose = self._bone(address, params)
                if pose is not None:
                    updated[pose[0]] = pose[1]
            elif address == TIME:
                bad_time = True
                if len(params) < 1 or not isinstance(params[0], (int, float)) or isinstance(params[0], bool):
                    c.malformed_messages += 1
                elif not math.isfinite(params[0]):
                    c.non_finite += 1
                elif abs(params[0]) > MAX_SENDER_TIME_S:
                    c.out_of_range += 1
                else:
                    bad_time = False
                    device_ns = int(round(float(params[0]) * 1e9))
            # every other VMC address (/VMC/Ext/OK, blend shapes, camera, ...) is not needed here
        if not updated or bad_time:
            return None
        stamp = receive_ns
        if device_ns is not None:
            if self._last_device_ns is not None and device_ns < self._last_device_ns - _RESYNC_NS:
                self._outliers_before += self._sync.rejected
                self._sync = ClockSync()
                self._steps.clear()  # a new sender (or a restarted one) has its own frame period
            rejected = self._sync.rejected
            stamp = self._sync.observe(device_ns, receive_ns)
            if self._sync.rejected == rejected:  # an outlier is no sign of a sender restart either
                self._count_missing(device_ns)
                self._last_device_ns = device_ns
                self._outliers_between = 0
            else:
                self._outliers_between += 1  # received, so not missing, though its stamp is not used
            c.clock_outliers = self._outliers_before + self._sync.rejected
        self._bones.update(updated)
        c.frames += 1
        return Frame(receive_ns, stamp, frozenset(updated), dict(self._bones))

    def _count_missing(self, device_ns: int) -> None:
        """Frames missing between the last sender time and this one: a step of k sender periods (the
        median step) lost k - 1 frames. Steps of 0 (a skeleton split over bundles), backwards or over a
        second count none."""
        last = self._last_device_ns
        if last is None or device_ns <= last or device_ns - last > _RESYNC_NS:
            return  # (a jump of more than a second is a pause or a clock jump, and the runner reports gaps)
        step = device_ns - last
        if len(self._steps) >= _PERIOD_MIN_STEPS:
            period = statistics.median(self._steps)
            missing = round(step / period) - 1 - self._outliers_between
            if missing > 0:
                self.counters.lost_sequence_gaps += missing
        self._steps.append(step)  # (a gap now and then does not move the median; a new frame rate does)

    def _bone(self, address: str, params: list) -> tuple[str, BonePose] | None:
        c = self.counters
        if len(params) < 8 or not isinstance(params[0], str) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in params[1:8]):
            c.malformed_messages += 1
            return None
        name = params[0]
        if address == BONE and name not in KNOWN_BONES:
            c.unknown_bones += 1
            return None
        values = np.array(params[1:8], dtype=float)
        if not np.all(np.isfinite(values)):
            c.non_finite += 1
            return None
        if np.max(np.abs(values[:3])) > MAX_POSITION_M:
            c.out_of_range += 1
            return None
        q = values[3:]
        if np.max(np.abs(q)) > 2.0 or abs(float(np.linalg.norm(q)) - 1.0) > UNIT_TOLERANCE:
            c.non_unit_rotations += 1  # (the first test keeps the norm itself from overflowing)
            return None
        return ("" if address == ROOT else name), BonePose(values[:3], q / np.linalg.norm(q))


class _OscWarnings(logging.Filter):
    """python-osc warns on the root logger, with the whole datagram, about every bundle element and type
    tag it cannot read (and skips it): junk from a stranger would flood the terminal. Those warnings are
    kept off the log and counted per thread, so the receiver counts the element as a malformed message."""

    def __init__(self):
        super().__init__()
        self.local = threading.local()
        self.package = str(Path(pythonosc.__file__).parent)

    def filter(self, record: logging.LogRecord) -> bool:
        if record.pathname.startswith(self.package):
            self.local.count = self.count() + 1
            return False
        return True

    def count(self) -> int:
        return getattr(self.local, "count", 0)


_OSC_WARNINGS = _OscWarnings()
logging.getLogger().addFilter(_OSC_WARNINGS)


"""The operator calibration a rig references: per-joint scale and offset for the hand mapping, and the
yaw between the suit's world frame and the robot's base frame. `teleprev calibrate` writes it.

    [calibration]
    suit_yaw = 0.0            # rad: the robot's +x as seen in the suit frame, so "forward" is forward
    [joints."1"]              # a LEAP joint: q = sign * scale * angle + offset (sign and source fixed)
    scale = 1.1
    offset = -0.05
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from teleprev.config import from_table, read_toml
from teleprev.errors import ConfigError
from teleprev.retarget.hand import DEFAULT_LEAP_MAP, JointMap


@dataclass(frozen=True)
class JointCalibration:
    scale: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class CalibrationSection:
    suit_yaw: float = 0.0
    created: str = ""
    operator: str = ""


@dataclass(frozen=True)
class Calibration:
    calibration: CalibrationSection = field(default_factory=CalibrationSection)
    joints: dict[str, JointCalibration] = field(default_factory=dict)

    def leap_map(self) -> dict[str, JointMap]:
        return {
            name: replace(m, scale=self.joints[name].scale, offset=self.joints[name].offset)
            if name in self.joints
            else m
            for name, m in DEFAULT_LEAP_MAP.items()
        }

    def suit_to_robot(self) -> np.ndarray:
        c, s = np.cos(self.calibration.suit_yaw), np.sin(self.calibration.suit_yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def load_calibration(path: str | Path | None) -> Calibration:
    if not path:
        return Calibration()
    return parse_calibration(read_toml(path), str(path))


def load_calibration_text(text: str, where: str) -> Calibration:
    """A calibration from TOML text (a session keeps a copy in its metadata); empty text: the defaults."""
    import tomllib

    if not text.strip():
        return Calibration()
    try:
        return parse_calibration(tomllib.loads(text), where)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML ({exc})", where) from None


def parse_calibration(data: dict, where: str) -> Calibration:
    cal = from_table(Calibration, data, where)
    unknown = sorted(set(cal.joints) - set(DEFAULT_LEAP_MAP))
    if unknown:
        raise ConfigError(f"unknown LEAP joint {unknown[0]!r} in [joints] (joints are \"0\"..\"15\")", where)
    return cal


def write_calibration(cal: Calibration, path: str | Path) -> Path:
    """Write the calibration file (its folder is created if need be)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(calibration_toml(cal))
    return path


def calibration_toml(cal: Calibration) -> str:
    """The calibration file's text."""
    import json

    lines = [
        "# Operator calibration written by `teleprev calibrate`; a rig points at it with [rig] calibration = ...",
        "[calibration]",
        f"suit_yaw = {float(cal.calibration.suit_yaw)!r}",
        f'created = "{cal.calibration.created or _dt.datetime.now().isoformat(timespec="seconds")}"',
        f"operator = {json.dumps(cal.calibration.operator)}",  # a TOML basic string: JSON's escapes
        "",
    ]
    for name in sorted(cal.joints, key=int):
        j = cal.joints[name]
        lines += [f'[joints."{name}"]', f"scale = {float(j.scale)!r}", f"offset = {float(j.offset)!r}", ""]
    return "\n".join(lines)

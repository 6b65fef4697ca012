"""Errors a user can act on.

Every error names *what* is wrong and *where* (a file, an element, a device, a stream), so the CLI can
print one clear line instead of a traceback.
"""

from __future__ import annotations


class TeleprevError(Exception):
    """Base class: `where` is the file, element, device or stream the problem is in."""

    def __init__(self, message: str, where: str | None = None):
        super().__init__(message)
        self.message = message
        self.where = where

    def __str__(self) -> str:
        return f"{self.where}: {self.message}" if self.where else self.message


class ConfigError(TeleprevError):
    """A rig, calibration, recipe or tolerance file is malformed."""


class UrdfError(TeleprevError):
    """A robot description is missing, malformed or refers to something that does not exist."""


class ModelError(TeleprevError):
    """A trained model file is missing, corrupted or does not match the robot."""


class SessionError(TeleprevError):
    """A recorded session is missing, truncated or lacks what was asked for."""


class DeviceError(TeleprevError):
    """A device could not be opened, stopped sending or sent something unusable."""


def describe_os_error(exc: BaseException) -> str:
    """An I/O error in a few words: "no space left on device" rather than "[Errno 28] No space ...";
    file-size limits (RLIMIT_FSIZE) read as what they are."""
    import errno

    code = getattr(exc, "errno", None)
    if code == errno.ENOSPC:
        return "no space left on device"
    if code == errno.EFBIG:
        return "file too large (a file-size limit was reached)"
    if code == errno.EDQUOT:
        return "disk quota exceeded"
    text = getattr(exc, "strerror", None) or str(exc)
    return text[:1].lower() + text[1:] if text else type(exc).__name__

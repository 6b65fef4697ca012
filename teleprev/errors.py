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


class DeviceStartError(DeviceError):
    """A device that cannot start, and trying again will not change that: the port it must listen on is
    taken, the folder it must write cannot be written. Its runner stops trying, and a recording waiting
    for its devices fails at once, naming it."""


def describe_exception(exc: BaseException) -> str:
    """An error in words for a one-line message, never empty: a teleprev error's own text; any other as its
    type and text; one whose text is empty (TimeoutError(), a DeviceError with no message) as its type,
    where it happened, and what it was raised from."""
    if isinstance(exc, TeleprevError):
        if exc.message:
            return str(exc)
        text = f"{type(exc).__name__}" + (f" in {exc.where}" if exc.where else "")
    else:
        said = str(exc)
        if said:
            return f"{type(exc).__name__}: {said}"
        text = type(exc).__name__
    cause = exc.__cause__ or (None if exc.__suppress_context__ else exc.__context__)
    return f"{text} (from {describe_exception(cause)})" if cause is not None and cause is not exc else text


def describe_os_error(exc: BaseException) -> str:
    """An I/O error in a few words: "no space left on this device" rather than "[Errno 28] No space ..."."""
    said = out_of_space(exc)
    if said:
        return said
    text = getattr(exc, "strerror", None) or str(exc)
    return text[:1].lower() + text[1:] if text else type(exc).__name__


_SPACE_ERRNOS = {28: ("No space left on device", "no space left on this device"),
                 27: ("File too large", "a file reached the size limit (ulimit -f)"),
                 122: ("Disk quota exceeded", "the disk quota is exceeded")}


def out_of_space(exc: BaseException | None) -> str:
    """What ran out, when an error or one it was raised from is a full disk (ENOSPC), a file-size limit
    (EFBIG) or a quota (EDQUOT), including errors a library re-raised as text (an encoder thread's
    RuntimeError, a worker's failure message); "" otherwise."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        code = getattr(exc, "errno", None)
        if code in _SPACE_ERRNOS:
            return _SPACE_ERRNOS[code][1]
        text = str(exc)
        for n, (strerror, said) in _SPACE_ERRNOS.items():
            if f"[Errno {n}]" in text or strerror in text:
                return said
        exc = exc.__cause__ or exc.__context__
    return ""

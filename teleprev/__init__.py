"""teleprev: teleoperation with preview, self-collision correction and synchronized recording."""

from teleprev import numeric_platform as _numeric_platform

_numeric_platform.pin()  # before anything imports numpy

__version__ = "0.1.0"

"""teleprev: teleoperation with preview, self-collision correction and synchronized recording."""

__version__ = "0.1.0"

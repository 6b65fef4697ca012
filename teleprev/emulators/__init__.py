"""Emulated hardware that the real SDKs drive, unmodified: for tests, benchmarks and dry runs of a rig.

    xarm_controller.XArmController   an xArm control box on a loopback address: xarm-python-sdk's TCP
                                     protocol on port 502 and the report streams on 30001-30003
    dynamixel_bus.DynamixelBus       a Dynamixel Protocol 2.0 bus on a pseudo-terminal with the LEAP Hand's
                                     16 XC330 motors behind an FTDI adapter, opened by dynamixel-sdk
    mjpeg_stream.MjpegServer         a camera over HTTP (multipart MJPEG), as IP cameras serve it

Each emulator enforces what the real device enforces, injects the faults the real device has
(`inject(...)`), and counts what it saw, so a test can check that a fault reached the user. The CLI's
`teleprev devices emulate xarm|leap` runs one for a dry run and prints the rig keys that point at it.
Every behaviour, timing included, comes from the vendors' manuals or the SDKs' source, cited next to it; the
code is ours. tests/devices/test_emulator_conformance.py checks each through the real SDK.
"""

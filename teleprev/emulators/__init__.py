"""Emulated hardware that the real SDKs drive, unmodified: for tests, benchmarks and dry runs of a rig.

    xarm_controller.XArmController   an xArm control box on a loopback address: xarm-python-sdk's TCP
                                     protocol on port 502 and the report stream on 30001/30002
    dynamixel_bus.DynamixelBus       a Dynamixel Protocol 2.0 bus on a pseudo-terminal with the LEAP Hand's
                                     16 motors, opened by pyserial / dynamixel-sdk like a USB adapter
    mjpeg_stream.MjpegServer         a camera over HTTP (multipart MJPEG), as IP cameras serve it

Each emulator enforces what the real device enforces, injects the faults the real device has
(`inject(...)`), and counts what it saw, so a test can check that a fault reached the user. The CLI's
`teleprev devices emulate xarm|leap` runs one for a dry run and prints the rig keys that point at it.
Protocol facts come from the vendors' manuals and the SDKs' documented behaviour; the code is ours.
"""

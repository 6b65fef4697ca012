"""The robot's actuators in the physics world, in SI units, and where each number comes from.

Every joint is position-controlled like the real servo it stands for: a PD law
`torque = kp (target - q) - kd q_dot`, clamped to the drive's force limit, acting on the joint through
the reflected inertia of its motor (`armature`).

xArm6 (joint1..joint6). The controller's servo mode runs the latest joint target with a stiff joint loop
and compensates gravity from its own dynamic model (xarm-python-sdk: set_servo_angle_j). We model it as
PD with a closed-loop bandwidth of about 25 Hz on the reflected inertia of a harmonic-drive joint
(armature 0.1 kg m^2, an estimate: a ~1e-5 kg m^2 rotor behind a 1:100 reduction), damping ratio 0.7
(it lags a 1 rad/s ramp by about 9 mrad; the real controller's bandwidth is not published),
torque-limited at the URDF's effort (50 N m, xarm_ros2's description), with gravity compensated on the
arm links and the end effector's mount (the controller's payload setting).

LEAP Hand (joints "0".."15"). Dynamixel XC330-M288-T servos in current-based position control with the
LEAP driver's registers: Position P Gain 600, D Gain 200 (x 0.75 on the side-to-side joints "0", "4",
"8"), current limit 550 mA (the Full hand; the Lite uses 350 mA). The X series' position loop scales its
registers as KPP = P / 128 and KPD = D / 16 (ROBOTIS e-Manual, X series control diagram), with the error
in encoder pulses (4096 per turn), the error's change per millisecond for D, and the output in mA
(the XC330's current unit is 1 mA). Current turns into joint torque through the torque constant at the
output shaft, 0.93 N m / 1.80 A = 0.517 N m / A (XC330-M288-T stall torque and stall current at 5 V,
e-Manual):
    kp = 600 / 128 mA/pulse * 4096 / (2 pi) pulse/rad * 0.517e-3 N m/mA       = 1.58 N m/rad
    kd = 200 / 16 mA/(pulse/ms) * 4096 / (2 pi) * 1e-3 s/ms * 0.517e-3 N m/mA = 4.2e-3 N m s/rad
    torque limit = 550 mA * 0.517 N m/A                                       = 0.284 N m
The rotor behind the 288.35:1 gearbox reflects about 1e-8 kg m^2 * 288^2 = 8e-4 kg m^2 (armature 1e-3,
an estimate for a coreless micro motor), and the metal gear train adds viscous loss (damping 0.05 N m s/rad,
an estimate that settles a finger step in about 0.1 s like the real hand).

Parallel-jaw gripper ("gripper", the jaw opening in metres). The URDF's jaws mimic the driver (MuJoCo
turns <mimic> into joint equalities), so the drive pushes each jaw with its own force: limited to 30 N
(an estimate of a light gripper's grip force), stiff enough to reach the target within a millimetre, and
no faster than the URDF's 0.15 m/s (viscous loss of 200 N s/m: 30 N at that speed).

Vacuum ("vacuum", 0 off / 1 on). MuJoCo's adhesion actuator on the suction cup: 42 N when on, the pull of
a 30 mm cup at 60 kPa below atmosphere (60e3 Pa * pi * 0.015^2 m^2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# Dynamixel X series register scaling and the XC330-M288-T (see the module docstring).
_PULSES_PER_RAD = 4096 / (2 * math.pi)
_XC330_NM_PER_MA = 0.93 / 1800.0


@dataclass(frozen=True)
class Drive:
    """A position-controlled joint drive, SI units (N m and rad, or N and m for a slide)."""

    kp: float  # per rad (m)
    kd: float  # per rad/s (m/s)
    force_limit: float
    armature: float = 0.0  # kg m^2 (kg)
    damping: float = 0.0  # passive viscous loss, per rad/s (m/s)


def dynamixel_drive(p_gain: int, d_gain: int, current_limit_ma: float) -> Drive:
    """An XC330-M288-T in current-based position control with these registers (see the docstring)."""
    ma_per_rad = p_gain / 128 * _PULSES_PER_RAD
    ma_per_rad_s = d_gain / 16 * _PULSES_PER_RAD * 1e-3
    return Drive(kp=ma_per_rad * _XC330_NM_PER_MA, kd=ma_per_rad_s * _XC330_NM_PER_MA,
                 force_limit=current_limit_ma * _XC330_NM_PER_MA, armature=1e-3, damping=0.05)


_ARM_ARMATURE = 0.1
_ARM_BANDWIDTH_HZ = 25.0
_ARM_DAMPING_RATIO = 0.7
_ARM_INERTIA = 0.3  # kg m^2: the armature plus a typical link inertia seen by the joint
_ARM_KP = (2 * math.pi * _ARM_BANDWIDTH_HZ) ** 2 * _ARM_INERTIA
ARM = Drive(kp=_ARM_KP, kd=2 * _ARM_DAMPING_RATIO * math.sqrt(_ARM_KP * _ARM_INERTIA), force_limit=50.0,
            armature=_ARM_ARMATURE)

LEAP_P_GAIN, LEAP_D_GAIN, LEAP_CURRENT_LIMIT_MA = 600, 200, 550.0
LEAP = dynamixel_drive(LEAP_P_GAIN, LEAP_D_GAIN, LEAP_CURRENT_LIMIT_MA)
LEAP_SIDE = dynamixel_drive(int(LEAP_P_GAIN * 0.75), int(LEAP_D_GAIN * 0.75), LEAP_CURRENT_LIMIT_MA)
LEAP_SIDE_JOINTS = ("0", "4", "8")

# The motor and its gearing hold the jaws to the URDF's 0.15 m/s: 30 N / 0.15 m/s of viscous loss.
GRIPPER = Drive(kp=3000.0, kd=30.0, force_limit=30.0, armature=0.05, damping=200.0)
VACUUM_FORCE_N = 60e3 * math.pi * 0.015**2

"""The physical sim world (MuJoCo): the robot from our URDFs with position-controlled drives, the table and
each task's objects as rigid bodies, stepped on the session clock; cameras that give colour and depth;
and each task's success read from the physics state.

    layout.py   what stands on the table per task, drawn from a seed
    drives.py   the arm's, hand's, gripper's and vacuum's actuators, with where their numbers come from
    build.py    compiling robot + drives + table + objects + cameras into one MuJoCo model
    world.py    PhysicsWorld: step to a session time, targets and positions by joint name, object states
    camera.py   WorldCamera: RGB and depth (metres) from a named camera
    success.py  each task's success with its reason, from the world's states over time

Importing this package imports mujoco: only the commands and devices that run the physics world do.
Rendering is headless unless asked otherwise: without a display and without MUJOCO_GL, MuJoCo renders
through EGL (Mesa's, in software, where there is no GPU).
"""

import os
import sys

if sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"  # read by mujoco when it is first imported, below this package

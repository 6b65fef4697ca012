"""Simulated devices: an operator performing the paper's five tasks (glove and suit streams), a camera
that renders the scene with the robot in it, and a kinematic arm and hand. The default rig
(rigs/sim.toml) is made of them, so teleprev runs on any machine.

    operator.py  the person (tasks.py: task scripts, grasps.py: hand shapes)
    world.py     robot state and task objects shared by the devices of a rig
    device.py    pacing, device clock, transport delay, ClockSync, ground truth (clock.py)
    glove.py suit.py (operated.py) camera.py (render.py) arm.py hand.py (actuator.py, follow.py)   the plugins
"""

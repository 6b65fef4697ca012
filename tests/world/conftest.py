import os

# Headless rendering through EGL, decided before anything imports mujoco (it reads MUJOCO_GL on import).
os.environ.setdefault("MUJOCO_GL", "egl")

"""The default sim rig with the emulated xArm controller and LEAP Hand bus in place of the sim arm and hand:
the simulated operator drives the real plugins and SDKs (tests/live/test_wire_process.py, bench/hardware.py).

    rig.write_text(sim_operator_rig(box.rig_keys("arm"), bus.rig_keys("hand"), camera=False))
"""

from __future__ import annotations

import re

from teleprev.rig import default_rig_path


def _section(text: str, name: str, replacement: str) -> str:
    """`text` with the TOML table [name] (up to the next table or comment block) replaced."""
    return re.sub(rf"\[{re.escape(name)}\].*?(?=\n\[|\n#|\Z)", replacement.rstrip("\n"), text, count=1, flags=re.S)


def sim_operator_rig(arm_keys: str, hand_keys: str, camera: bool = True) -> str:
    text = _section(default_rig_path().read_text(), "devices.arm", arm_keys)
    text = _section(text, "devices.hand", hand_keys)
    if not camera:
        text = _section(_section(text, "devices.cam_front", ""), "frames.cam_front", "")
    return text

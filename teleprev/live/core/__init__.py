"""The session loop and what it needs, shared by recording and rollout: the loop (one thread orders every
sample and control), its typed controls, the execute gate, the relay to the actuators, episodes, and the
paced command sender (a process of its own) with its pipe codec."""

"""How the CPN splits a robot into groups of joints that can collide with each other.

Two links can only collide through the joints that move one of them. For a hand those are two fingers
(eight joints), so per-link collision is an OR over finger pairs of functions of eight joints each, which
is far easier to learn than one function of all sixteen. A group is one such joint set (a maximal union of
the joints moving the two links of a checked pair); every checked link pair goes to the first group
containing its joints, and is one output slot of that group's sub-network. A link's collision probability
is the noisy-OR of the slots it appears in:  p(link) = 1 - prod(1 - sigmoid(z_slot)).

For a robot whose pairs all involve every joint this degenerates to one group: a plain MLP.
"""

from __future__ import annotations

from dataclasses import dataclass

from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import RobotModel


@dataclass(frozen=True)
class Group:
    inputs: tuple[str, ...]  # joint names
    outputs: tuple[tuple[str, ...], ...]  # per output slot: the links (CPN) or joint (CCN) it feeds

    def to_json(self) -> dict:
        return {"inputs": list(self.inputs), "outputs": [list(o) for o in self.outputs]}

    @staticmethod
    def from_json(data: dict) -> Group:
        return Group(tuple(data["inputs"]), tuple(tuple(o) for o in data["outputs"]))


def moving_joints(model: RobotModel, link: str) -> frozenset[int]:
    """Actuated joints (by index; a mimic joint counts as its driver) that move `link` relative to the root."""
    out = set()
    while link in model.parent_joint:
        joint = model.parent_joint[link]
        if joint.type != "fixed":
            out.add(model.joint_index[joint.mimic.joint if joint.mimic else joint.name])
        link = joint.parent
    return frozenset(out)


def collision_groups(model: RobotModel, checker: SelfCollisionChecker) -> tuple[Group, ...]:
    unions = [moving_joints(model, a) | moving_joints(model, b) for a, b in checker.link_pairs]
    maximal = sorted({u for u in unions if not any(u < v for v in unions)}, key=sorted)
    slots: list[list[tuple[str, str]]] = [[] for _ in maximal]
    for pair, u in zip(checker.link_pairs, unions):
        slots[next(i for i, v in enumerate(maximal) if u <= v)].append(pair)
    return tuple(
        Group(tuple(model.joint_names[j] for j in sorted(joints)), tuple(slot))
        for joints, slot in zip(maximal, slots) if slot
    )


def single_group(inputs: tuple[str, ...], outputs: tuple[str, ...]) -> tuple[Group, ...]:
    """A plain MLP: every input feeds every output, one output slot per name."""
    return (Group(tuple(inputs), tuple((o,) for o in outputs)),)

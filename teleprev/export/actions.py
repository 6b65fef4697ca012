"""A LeRobot dataset's `action` column, read from its parquet files without lerobot (the live path must
not import it), with a rig's arm and end-effector joints found in it by name: what `teleprev audit
DATASET` checks and `teleprev replay DATASET` plays.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev.errors import SessionError


def is_dataset(path: Path) -> bool:
    return (Path(path) / "meta" / "info.json").is_file()


def _action_columns(names: list[str], joints: tuple[str, ...], prefix: str, side: str = "") -> list[int] | None:
    """Where each joint sits among the action's names: "<prefix>.<joint>" (teleprev's exports), else
    "<anything>.<joint>" or "<joint>" met exactly once; None if a joint is not found. With a `side`, only
    that side's names count: "<side>_<prefix>.<joint>", else "<side>_<anything>.<joint>" met once (LeRobot's
    bimanual naming)."""
    if side:
        names = [n[len(side) + 1:] if n.startswith(f"{side}_") else "" for n in names]
    out = []
    for j in joints:
        exact = [i for i, n in enumerate(names) if n == f"{prefix}.{j}"]
        loose = [i for i, n in enumerate(names) if (n == j and not side) or n.endswith("." + j)]
        found = exact or (loose if len(loose) == 1 else [])
        if not found:
            return None
        out.append(found[0])
    return out


@dataclass
class DatasetActions:
    """A LeRobot dataset's `action` column, with the rig's arm and end-effector joints found in it."""

    episodes: np.ndarray  # per frame
    stamps: np.ndarray  # per frame: its timestamp in ns (from its episode's start)
    action: np.ndarray  # (frames, action values)
    arm_cols: list[int]  # the rig's arm joints, in its order, among the action's values
    hand_cols: list[int]
    note: str = ""  # how the joints were matched, when not by name

    def episode(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(stamps, actions) of one episode in time order."""
        rows = np.flatnonzero(self.episodes == index)
        rows = rows[np.argsort(self.stamps[rows], kind="stable")]
        return self.stamps[rows], self.action[rows]


def read_actions(root: str | Path, limits: dict, side: str = "") -> DatasetActions:
    """The `action` column of a LeRobot dataset (teleprev's or anyone's) read from its parquet files
    (without lerobot), its joints matched to the rig's `limits` by name ("arm.joint1" or "joint1"); when
    no name matches and the action has exactly the rig's arm + end-effector joints, by position.

    `side` ("left", "right"): one side of a bimanual dataset, `limits` being that side's: its joints by
    name ("left_arm.joint1"), else by position when the action has exactly both sides' joints, left first."""
    import pyarrow.parquet as pq

    root = Path(root)
    where = str(root / "meta" / "info.json")
    try:
        info = json.loads((root / "meta" / "info.json").read_text())
        feature = info["features"]["action"]
    except (OSError, ValueError, KeyError) as e:
        raise SessionError(f"not a LeRobot dataset with an 'action' feature ({type(e).__name__}: {e})", where) from None
    names = feature.get("names")
    if isinstance(names, dict):  # older datasets: {"motors": [...]}
        names = next(iter(names.values()), None)
    names = [str(n) for n in names] if names else [f"action.{i}" for i in range(int(feature["shape"][0]))]
    arm_names, hand_names = limits["arm"]["names"], limits["hand"]["names"]
    arm_cols = _action_columns(names, arm_names, "arm", side)
    hand_cols = _action_columns(names, hand_names, "hand", side)
    note = ""
    if arm_cols is None or hand_cols is None:
        per_side = len(arm_names) + len(hand_names)
        if len(names) != per_side * (2 if side else 1):
            whose = f"the {side} side's joints ({side}_arm.joint1 ...; {per_side} a side)" if side else \
                "the rig's joints"
            raise SessionError(f"the action's {len(names)} names {names[:8]}{'...' if len(names) > 8 else ''} do not "
                               f"name {whose} ({len(arm_names)} arm: {list(arm_names)}; {len(hand_names)} "
                               f"end effector), and their number differs, so they cannot be matched by position", where)
        first = per_side if side == "right" else 0
        arm_cols = list(range(first, first + len(arm_names)))
        hand_cols = list(range(first + len(arm_names), first + per_side))
        note = "joints matched by position (the action's names are not the rig's)"
    files = sorted((root / "data").rglob("*.parquet"))
    if not files:
        raise SessionError("no data/*.parquet files", str(root))
    table = {"episode_index": [], "timestamp": [], "action": []}
    for f in files:
        try:
            part = pq.read_table(f, columns=list(table)).to_pydict()
        except Exception as e:  # pyarrow raises many kinds for a damaged or foreign file
            raise SessionError(f"cannot read the columns episode_index, timestamp, action ({e})", str(f)) from None
        _check_finite(part, names, f)
        for k in table:
            table[k].extend(part[k])
    return DatasetActions(np.asarray(table["episode_index"], dtype=np.int64),
                          np.round(np.asarray(table["timestamp"], dtype=float) * 1e9).astype(np.int64),
                          np.asarray(table["action"], dtype=float), arm_cols, hand_cols, note)


def _check_finite(part: dict, names: list[str], where: Path) -> None:
    """Refuse a NaN or infinite action or timestamp (a player's jerk-limited generator and the audit's
    differences cannot measure one), naming the first: its row, episode, time and joint."""
    action = np.asarray(part["action"], dtype=float)
    stamps = np.asarray(part["timestamp"], dtype=float)
    bad_stamp = np.flatnonzero(~np.isfinite(stamps))
    bad_action = np.argwhere(~np.isfinite(action)) if action.ndim == 2 else np.zeros((0, 2), int)
    if not len(bad_stamp) and not len(bad_action):
        return
    row = min(bad_stamp[0] if len(bad_stamp) else len(stamps), bad_action[0][0] if len(bad_action) else len(stamps))
    episode = part["episode_index"][row]
    if len(bad_stamp) and bad_stamp[0] == row:
        raise SessionError(f"timestamp is {stamps[row]} in row {row} (episode {episode}): not a time", str(where))
    col = int(bad_action[0][1])
    name = names[col] if col < len(names) else f"action[{col}]"
    raise SessionError(f"action {name!r} is {action[row, col]} in row {row} (episode {episode}, timestamp "
                       f"{stamps[row]:g} s): only finite joint positions can be replayed or audited", str(where))

"""The CPN and CCN as numpy MLPs, and their safetensors files.

Runtime inference is numpy only (the live pipeline must not import torch). A network is G parallel MLPs
of the same depth, one per group of inputs (groups.py); the CCN is one group (a plain MLP). Group g
reads its input joints, padded with zeros to the widest group, and writes its output slots, padded
likewise. A model file holds float32 tensors `layers.<i>.weight` (G, in, out) and `layers.<i>.bias`
(G, out), and string metadata:

    format        "teleprev-noncollision/1"
    kind          "cpn" | "ccn"
    robot, urdf_sha256, joint_names (JSON)     what the network was trained for
    link_names (JSON)                          the CPN's outputs (the checker's link order)
    groups (JSON)                              per group: input joints, and what each output slot feeds
    combine                                    "identity" (slot = output) | "noisy_or" (CPN: see groups.py)
    hidden (JSON), activation                  the architecture
    input_offset, input_scale (JSON)           features x = (q - offset) / scale, per joint
    threshold                                  CPN: operating threshold on the per-link probability
    output_scale (JSON)                        CCN: q_hat = clip(q + output_scale * net(x))
    training (JSON)                            settings, history and metrics, for the record

`load_model` refuses a file that is not safetensors, lacks a key, has tensors of the wrong shape, or was
trained for another robot or URDF version, with a message naming the file and the problem.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from teleprev.errors import ModelError
from teleprev.noncollision.groups import Group

FORMAT = "teleprev-noncollision/1"
ACTIVATIONS = ("silu", "relu", "tanh")
COMBINES = ("identity", "noisy_or")


def sigmoid(z: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * z))  # no overflow for large |z|


def softplus(z: np.ndarray) -> np.ndarray:
    return np.logaddexp(0.0, z)


def _act(z: np.ndarray, kind: str) -> np.ndarray:
    if kind == "relu":
        return np.maximum(z, 0.0)
    if kind == "tanh":
        return np.tanh(z)
    return z * sigmoid(z)


def _act_grad(z: np.ndarray, kind: str) -> np.ndarray:
    if kind == "relu":
        return (z > 0).astype(z.dtype)
    if kind == "tanh":
        return 1.0 - np.tanh(z) ** 2
    s = sigmoid(z)
    return s * (1.0 + z * (1.0 - s))


@dataclass(frozen=True)
class ModelInfo:
    kind: str
    robot: str
    urdf_sha256: str
    joint_names: tuple[str, ...]
    link_names: tuple[str, ...]
    groups: tuple[Group, ...]
    combine: str
    hidden: tuple[int, ...]
    activation: str
    input_offset: np.ndarray
    input_scale: np.ndarray
    threshold: float | None = None
    output_scale: np.ndarray | None = None
    training: dict | None = field(default=None, compare=False)

    @property
    def outputs(self) -> tuple[str, ...]:
        """What the network's outputs are: links (CPN) or joints (CCN)."""
        return self.link_names if self.kind == "cpn" else self.joint_names

    @property
    def width_in(self) -> int:
        return max(len(g.inputs) for g in self.groups)

    @property
    def width_out(self) -> int:
        return max(len(g.outputs) for g in self.groups)

    def layer_shapes(self) -> list[tuple[int, int, int]]:
        sizes = [self.width_in, *self.hidden, self.width_out]
        return [(len(self.groups), sizes[i], sizes[i + 1]) for i in range(len(sizes) - 1)]

    def input_index(self) -> np.ndarray:
        """(G, width_in) indices into the joint vector, padding pointing at an extra zero feature."""
        pos = {n: i for i, n in enumerate(self.joint_names)}
        pad = len(self.joint_names)
        return np.array([[pos[n] for n in g.inputs] + [pad] * (self.width_in - len(g.inputs)) for g in self.groups])

    def slot_matrix(self) -> np.ndarray:
        """(G * width_out, n_outputs) 0/1: which outputs each slot feeds (padding slots feed none)."""
        pos = {n: i for i, n in enumerate(self.outputs)}
        m = np.zeros((len(self.groups) * self.width_out, len(self.outputs)), dtype=np.float32)
        for g, group in enumerate(self.groups):
            for k, names in enumerate(group.outputs):
                m[g * self.width_out + k, [pos[n] for n in names]] = 1.0
        return m

    def metadata(self) -> dict[str, str]:
        meta = {
            "format": FORMAT,
            "kind": self.kind,
            "robot": self.robot,
            "urdf_sha256": self.urdf_sha256,
            "joint_names": json.dumps(list(self.joint_names)),
            "link_names": json.dumps(list(self.link_names)),
            "groups": json.dumps([g.to_json() for g in self.groups]),
            "combine": self.combine,
            "hidden": json.dumps(list(self.hidden)),
            "activation": self.activation,
            "input_offset": json.dumps([float(v) for v in self.input_offset]),
            "input_scale": json.dumps([float(v) for v in self.input_scale]),
            "training": json.dumps(self.training or {}),
        }
        if self.threshold is not None:
            meta["threshold"] = repr(float(self.threshold))
        if self.output_scale is not None:
            meta["output_scale"] = json.dumps([float(v) for v in self.output_scale])
        return meta


class MLP:
    """G parallel MLPs (float32), activation between layers, none after the last; raw slot outputs.

    The input normalisation is folded into the first layer at load (W0 / scale, b0 - offset / scale @ W0),
    so a forward pass is one gather and one batched matmul per layer.
    """

    def __init__(self, info: ModelInfo, weights: list[np.ndarray], biases: list[np.ndarray]):
        self.info = info
        self.activation = info.activation
        self.w = [np.ascontiguousarray(w, dtype=np.float32) for w in weights]  # (G, in, out), as stored
        self.b = [np.asarray(b, dtype=np.float32)[:, None, :] for b in biases]  # (G, 1, out)
        n = len(info.joint_names)
        index = info.input_index()
        offset = np.append(np.asarray(info.input_offset, dtype=np.float64), 0.0)[index]  # (G, width_in)
        inv_scale = np.append(1.0 / np.asarray(info.input_scale, dtype=np.float64), 0.0)[index]
        # Padding inputs get zero weights once folded, so they may read any joint: joint 0, no extra column.
        self._index = np.where(index == n, 0, index)
        w0 = self.w[0].astype(np.float64) * inv_scale[:, :, None]
        self._w = [w0.astype(np.float32)] + self.w[1:]
        self._b = [(self.b[0] - np.einsum("gi,gio->go", offset, w0)[:, None, :]).astype(np.float32)] + self.b[1:]
        self._n = n
        # (G, width_in, n + 1): routes input gradients back to the joints (for the backward pass); padding
        # rows go to the extra column, dropped
        self._route = np.zeros((len(info.groups), info.width_in, n + 1), dtype=np.float32)
        for g in range(len(info.groups)):
            self._route[g, np.arange(info.width_in), index[g]] = 1.0
        self._relu = self.activation == "relu"

    def _inputs(self, q: np.ndarray) -> np.ndarray:
        """(G, N, width_in) raw joint values per group for configurations (N, n)."""
        # contiguous, or matmul leaves BLAS for a slow generic loop
        return np.ascontiguousarray(np.swapaxes(np.asarray(q, dtype=np.float32)[:, self._index], 0, 1))

    def slots(self, q: np.ndarray) -> np.ndarray:
        """Raw outputs (N, G * width_out) for configurations (N, n); (G * width_out,) for one (n,).

        The single-configuration path is the one the live pipeline takes, so it avoids every copy it can.
        """
        single = q.ndim == 1
        h = np.asarray(q, dtype=np.float32)[self._index][:, None, :] if single else self._inputs(q)
        last = len(self._w) - 1
        for i, (w, b) in enumerate(zip(self._w, self._b)):
            h = h @ w
            h += b
            if i < last:
                if self._relu:
                    np.maximum(h, 0.0, out=h)
                else:
                    h = _act(h, self.activation)
        return h.reshape(-1) if single else np.swapaxes(h, 0, 1).reshape(len(q), -1)

    def slots_with_backward(self, q: np.ndarray):
        """Raw outputs (N, G * width_out) and a function mapping d/d(outputs) to d/dq (N, n)."""
        h = self._inputs(q)
        pre = []
        last = len(self._w) - 1
        for i, (w, b) in enumerate(zip(self._w, self._b)):
            z = h @ w + b
            if i < last:
                pre.append(z)
                h = _act(z, self.activation)
            else:
                h = z
        n_cfg = len(q)
        out = np.swapaxes(h, 0, 1).reshape(n_cfg, -1)

        def backward(d_out: np.ndarray) -> np.ndarray:
            g = np.swapaxes(np.asarray(d_out, dtype=np.float32).reshape(n_cfg, len(self._w[0]), -1), 0, 1)
            for i in range(last, -1, -1):
                g = g @ np.swapaxes(self._w[i], 1, 2)
                if i > 0:
                    g = g * _act_grad(pre[i - 1], self.activation)
            return np.einsum("gnd,gdj->nj", g, self._route)[:, :-1].astype(np.float64)

        return out, backward

    def tensors(self) -> dict[str, np.ndarray]:
        out = {}
        for i, (w, b) in enumerate(zip(self.w, self.b)):
            out[f"layers.{i}.weight"] = w
            out[f"layers.{i}.bias"] = np.ascontiguousarray(b[:, 0, :])
        return out


# ---- files --------------------------------------------------------------------------------------
def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def save_model(path: Path, net: MLP) -> Path:
    from safetensors.numpy import save_file

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    save_file(net.tensors(), str(tmp), metadata=net.info.metadata())
    tmp.chmod(0o644)
    tmp.replace(path)
    return path


def _json(meta: dict, key: str, where: str):
    try:
        return json.loads(meta[key])
    except KeyError:
        raise ModelError(f"metadata lacks {key!r} (not a teleprev CPN/CCN file?)", where) from None
    except json.JSONDecodeError:
        raise ModelError(f"metadata {key!r} is not valid JSON", where) from None


def _vector(meta: dict, key: str, n: int, where: str, positive: bool = False) -> np.ndarray:
    try:
        v = np.asarray(_json(meta, key, where), dtype=float)
    except (TypeError, ValueError):
        v = np.zeros(0)
    if v.shape != (n,) or not np.all(np.isfinite(v)) or (positive and np.any(v <= 0)):
        raise ModelError(f"metadata {key!r} must be {n} finite{' positive' if positive else ''} numbers", where)
    return v


def _groups(meta: dict, joint_names, outputs, where: str) -> tuple[Group, ...]:
    try:
        groups = tuple(Group.from_json(g) for g in _json(meta, "groups", where))
    except (KeyError, TypeError, AttributeError):
        raise ModelError("metadata 'groups' is malformed (expected a list of {inputs, outputs})", where) from None
    if not groups:
        raise ModelError("metadata 'groups' is empty", where)
    known_in, known_out = set(joint_names), set(outputs)
    for k, g in enumerate(groups):
        bad = [n for n in g.inputs if n not in known_in] + [n for o in g.outputs for n in o if n not in known_out]
        if bad or not g.inputs or not g.outputs:
            raise ModelError(f"group {k} names unknown joints/links {bad} or is empty", where)
    covered = {n for g in groups for o in g.outputs for n in o}
    if covered != known_out:
        raise ModelError(f"no output slot feeds {sorted(known_out - covered)}", where)
    return groups


def read_info(path: Path) -> tuple[ModelInfo, dict[str, np.ndarray]]:
    """Parse and check a model file's metadata and tensors (without a robot to compare against)."""
    from safetensors import safe_open

    path = Path(path)
    where = str(path)
    if not path.is_file():
        raise ModelError("no such model file", where)
    try:
        with safe_open(str(path), framework="numpy") as f:
            meta = dict(f.metadata() or {})
            tensors = {k: f.get_tensor(k) for k in f.keys()}
    except Exception as exc:  # safetensors raises its own error types for truncated or garbled files
        raise ModelError(f"not a readable safetensors file (truncated or corrupted?): {exc}", where) from None
    if meta.get("format") != FORMAT:
        raise ModelError(f"not a teleprev CPN/CCN file (format {meta.get('format')!r}, expected {FORMAT!r})", where)
    kind = meta.get("kind")
    if kind not in ("cpn", "ccn"):
        raise ModelError(f"unknown model kind {kind!r} (expected 'cpn' or 'ccn')", where)
    joint_names = tuple(_json(meta, "joint_names", where))
    link_names = tuple(_json(meta, "link_names", where))
    try:
        hidden = tuple(int(h) for h in _json(meta, "hidden", where))
    except (TypeError, ValueError):
        raise ModelError("metadata 'hidden' must be a list of layer widths", where) from None
    activation = meta.get("activation")
    if activation not in ACTIVATIONS:
        raise ModelError(f"unknown activation {activation!r} (expected one of {', '.join(ACTIVATIONS)})", where)
    combine = meta.get("combine")
    if combine not in COMBINES or (kind == "ccn" and combine != "identity"):
        raise ModelError(f"unknown output combination {combine!r} for a {kind.upper()}", where)
    n = len(joint_names)
    threshold = None
    if kind == "cpn":
        try:
            threshold = float(meta["threshold"])
        except (KeyError, ValueError):
            raise ModelError("CPN metadata lacks a numeric 'threshold'", where) from None
        if not 0.0 < threshold < 1.0:
            raise ModelError(f"CPN threshold {threshold} is not between 0 and 1", where)
    outputs = link_names if kind == "cpn" else joint_names
    info = ModelInfo(
        kind=kind, robot=meta.get("robot", ""), urdf_sha256=meta.get("urdf_sha256", ""),
        joint_names=joint_names, link_names=link_names, groups=_groups(meta, joint_names, outputs, where),
        combine=combine, hidden=hidden, activation=activation,
        input_offset=_vector(meta, "input_offset", n, where),
        input_scale=_vector(meta, "input_scale", n, where, positive=True),
        threshold=threshold,
        output_scale=_vector(meta, "output_scale", n, where) if kind == "ccn" else None,
        training=_json(meta, "training", where) if "training" in meta else None,
    )
    if combine == "identity" and any(len(o) != 1 for g in info.groups for o in g.outputs):
        raise ModelError("with combine 'identity' every output slot must feed exactly one output", where)
    expected = info.layer_shapes()
    names = {f"layers.{i}.{p}" for i in range(len(expected)) for p in ("weight", "bias")}
    arch = f"{len(info.groups)} x ({info.width_in}-{'-'.join(map(str, hidden))}-{info.width_out})"
    if set(tensors) != names:
        extra, missing = sorted(set(tensors) - names), sorted(names - set(tensors))
        raise ModelError(
            f"tensors do not match the architecture {arch} "
            f"(missing: {', '.join(missing) or 'none'}; unexpected: {', '.join(extra) or 'none'})", where,
        )
    for i, (g, a, b) in enumerate(expected):
        for key, want in ((f"layers.{i}.weight", (g, a, b)), (f"layers.{i}.bias", (g, b))):
            if tuple(tensors[key].shape) != want:
                raise ModelError(
                    f"tensor {key} has shape {tuple(tensors[key].shape)}, the architecture {arch} needs {want}", where
                )
            if not np.all(np.isfinite(tensors[key])):
                raise ModelError(f"tensor {key} holds non-finite values", where)
    return info, tensors


def load_model(path: Path, kind: str, robot, link_names: tuple[str, ...] | None = None) -> MLP:
    """A CPN or CCN for `robot` (a RobotModel): refused unless made for this URDF, these joints (and links)."""
    info, tensors = read_info(path)
    where = str(path)
    if info.kind != kind:
        raise ModelError(f"this is a {info.kind.upper()} file, a {kind.upper()} was expected", where)
    if info.urdf_sha256 != robot.urdf_sha256:
        raise ModelError(
            f"trained for a different URDF (sha256 {info.urdf_sha256[:12] or 'none'}…, {robot.urdf_path.name} is "
            f"{robot.urdf_sha256[:12]}…); retrain it for this robot (`teleprev collision train-{kind}`)", where,
        )
    if info.joint_names != tuple(robot.joint_names):
        raise ModelError(
            f"joint names {list(info.joint_names)} differ from the robot's {list(robot.joint_names)}", where
        )
    if link_names is not None and info.kind == "cpn" and info.link_names != tuple(link_names):
        raise ModelError(f"link names {list(info.link_names)} differ from the checker's {list(link_names)}", where)
    layers = len(info.layer_shapes())
    return MLP(
        info,
        [tensors[f"layers.{i}.weight"] for i in range(layers)],
        [tensors[f"layers.{i}.bias"] for i in range(layers)],
    )


# ---- the two networks at runtime --------------------------------------------------------------------
SCORE_BAND = 1e-3  # relative: scores this near the threshold are decided one configuration at a time
# (batched float32 sums differ from single ones by about 1e-6 of the score; tests/noncollision/test_mlp.py)

class CPN:
    """Per-link self-collision probability of configurations (numpy); q is (n,) or (N, n)."""

    def __init__(self, net: MLP):
        self.net = net
        self.threshold = float(net.info.threshold)
        self.link_names = net.info.link_names
        self.noisy_or = net.info.combine == "noisy_or"
        self._slots = net.info.slot_matrix()  # (slots, m)
        t = self.threshold
        self._free_below = np.float32(-np.log1p(-t) if self.noisy_or else np.log(t / (1.0 - t)))
        self.free_below = float(self._free_below)

    def _prob(self, slots: np.ndarray) -> np.ndarray:
        if self.noisy_or:
            return -np.expm1(-(softplus(slots) @ self._slots), dtype=np.float64)
        return sigmoid((slots @ self._slots).astype(np.float64))

    def prob(self, q: np.ndarray) -> np.ndarray:
        """Per-link probabilities (m,) for one configuration (n,), or (N, m) for (N, n)."""
        return self._prob(self.net.slots(np.asarray(q)))

    def score(self, q: np.ndarray) -> np.ndarray:
        """What the threshold compares, for configurations (N, n): the largest per-link sum (float32), free
        below `free_below`. Batched float32 sums may differ from a single configuration's in the last bits."""
        slots = self.net.slots(np.asarray(q))
        return (softplus(slots) @ self._slots if self.noisy_or else slots @ self._slots).max(axis=-1)

    def predicts_free(self, q: np.ndarray) -> np.ndarray:
        """Every link below the operating threshold (compared before the last, monotonic step)."""
        q = np.asarray(q)
        slots = self.net.slots(q)
        score = softplus(slots) @ self._slots if self.noisy_or else slots @ self._slots  # p < t <=> S < -log(1 - t)
        return bool(score.max() < self._free_below) if q.ndim == 1 else np.all(score < self._free_below, axis=-1)

    def mean_prob_grad(self, q: np.ndarray, scaled: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Mean link probability (N,) and its gradient w.r.t. q (N, n), for configurations (N, n).

        scaled: each row's gradient multiplied by a positive factor (its direction is exact) so that it
        does not underflow where the probability saturates deep inside collision.
        """
        slots, backward = self.net.slots_with_backward(np.atleast_2d(np.asarray(q, dtype=float)))
        p = self._prob(slots)
        m = p.shape[1]
        if self.noisy_or:  # p = 1 - exp(-S), S = sum softplus(z): dp/dz = (1 - p) * sigmoid(z) = exp(-S) sigmoid(z)
            s = (softplus(slots) @ self._slots).astype(np.float64)
            not_p = np.exp(-(s - s.min(axis=1, keepdims=True))) if scaled else np.exp(-s)
            d_slots = ((not_p / m) @ self._slots.T) * sigmoid(slots)
        else:
            d = p * (1.0 - p)
            d_slots = ((d / d.max(axis=1, keepdims=True) if scaled else d) / m) @ self._slots.T
        return p.mean(axis=1), backward(d_slots)


class CCN:
    """Corrected configuration for (invalid) configurations (numpy): clip(q + scale * net(x))."""

    def __init__(self, net: MLP, lower: np.ndarray, upper: np.ndarray):
        self.net = net
        self.lower, self.upper = lower, upper
        self.output_scale = np.asarray(net.info.output_scale, dtype=float)
        self._slots = net.info.slot_matrix()

    def __call__(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        delta = self.net.slots(q) @ self._slots
        return np.clip(q + self.output_scale * delta, self.lower, self.upper)

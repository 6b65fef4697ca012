"""Compiled CPN / CCN inference (teleprev.kernels.mlp) for Corrector(compiled=True), the live
pipeline's. The numpy networks (mlp.py) stay for training, gradients (projection) and compiled=False.

The kernels' loop order is fixed and a row's arithmetic does not depend on its batch, so a batch
answers bit for bit as single calls do (tests/noncollision/test_compiled_mlp.py); the answers agree with
the numpy networks to float32 rounding. Importing this module imports numba: only the Corrector does,
when asked for the compiled path (never `teleprev --help`).
"""

from __future__ import annotations

import numpy as np

from teleprev.kernels import mlp as mlp_kernels
from teleprev.noncollision.mlp import CCN, CPN, MLP

_ACTIVATION = {"relu": mlp_kernels.RELU, "silu": mlp_kernels.SILU, "tanh": mlp_kernels.TANH}


def pack(net: MLP) -> tuple[np.ndarray, np.ndarray]:
    """(net_i, net_w) for the kernels (layout: kernels' module docstring), from the folded weights."""
    info = net.info
    g, win, wout = len(info.groups), info.width_in, info.width_out
    header = [g, win, wout, len(net._w), len(info.joint_names), _ACTIVATION[info.activation],
              int(info.combine == "noisy_or"), len(info.outputs)]
    layers, chunks, offset = [], [], 0
    for w, b in zip(net._w, net._b):
        w = np.ascontiguousarray(w, dtype=np.float32)  # (G, in, out)
        b = np.ascontiguousarray(b[:, 0, :], dtype=np.float32)  # (G, out)
        layers += [offset, offset + w.size, w.shape[1], w.shape[2]]
        chunks += [w.ravel(), b.ravel()]
        offset += w.size + b.size
    matrix = info.slot_matrix()  # (slots, outputs)
    feeds = [np.flatnonzero(matrix[:, k]) for k in range(matrix.shape[1])]
    pointers = np.cumsum([0] + [len(f) for f in feeds])
    net_i = np.concatenate([header, np.asarray(net._index, dtype=np.int64).ravel(), layers, pointers,
                            np.concatenate(feeds) if feeds else []]).astype(np.int64)
    return net_i, np.concatenate(chunks).astype(np.float32)


def _rows(q) -> np.ndarray:
    return np.ascontiguousarray(np.atleast_2d(np.asarray(q, dtype=np.float64)))


class CompiledMLP:
    """The raw outputs of an MLP, compiled: slots(q) as MLP.slots (to float32 rounding)."""

    def __init__(self, net: MLP):
        self.net = mlp_kernels.Net(*pack(net))

    def slots(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q)
        out = mlp_kernels.slots(_rows(q), *self.net)
        return out[0] if q.ndim == 1 else out


class CompiledCPN:
    """A CPN whose threshold decision is compiled; the gradient (projection) stays numpy's."""

    def __init__(self, cpn: CPN):
        self.cpn = cpn
        self.mlp = CompiledMLP(cpn.net)
        t = cpn.threshold
        # p < t for every link  <=>  prod (1 + exp(z)) < 1 / (1 - t)  (noisy-or),  sum z < logit(t)  (identity)
        self.bound = float(1.0 / (1.0 - t) if cpn.noisy_or else np.log(t / (1.0 - t)))

    def predicts_free(self, q: np.ndarray):
        """As CPN.predicts_free: a bool for one configuration (n,), (N,) bools for (N, n)."""
        q = np.asarray(q)
        free = mlp_kernels.predicts_free(_rows(q), *self.mlp.net, self.bound)
        return bool(free[0]) if q.ndim == 1 else free

    def mean_prob_grad(self, q: np.ndarray, scaled: bool = False):
        return self.cpn.mean_prob_grad(q, scaled)

    def prob(self, q: np.ndarray) -> np.ndarray:
        return self.cpn._prob(self.mlp.slots(q))


class CompiledCCN:
    """The CCN's proposals, compiled: clip(q + scale * net(x)) as CCN.__call__ (to float32 rounding)."""

    def __init__(self, ccn: CCN):
        self.mlp = CompiledMLP(ccn.net)
        self.f = np.concatenate([ccn.lower, ccn.upper, ccn.output_scale]).astype(np.float64)

    def __call__(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q)
        out = mlp_kernels.propose(_rows(q), *self.mlp.net, self.f)
        return out[0] if q.ndim == 1 else out


class CompiledNets:
    """The Corrector's compiled CPN and CCN, and its fused CCN step (mlp_kernels.propose_shorten)."""

    def __init__(self, cpn: CPN, ccn: CCN, shorten_levels: int):
        self.cpn = CompiledCPN(cpn)
        self.ccn = CompiledCCN(ccn)
        self.steps = 2 ** shorten_levels
        self.step = mlp_kernels.CcnStep(*self.ccn.mlp.net, self.ccn.f, *self.cpn.mlp.net, self.cpn.bound, self.steps)

    def propose_shorten(self, q0: np.ndarray):
        """For colliding configurations q0 (N, n) within the limits: (proposals, shortened, hi), see kernels."""
        if q0.dtype != np.float64 or q0.ndim != 2 or not q0.flags.c_contiguous:  # the Corrector passes such rows
            q0 = _rows(q0)
        return mlp_kernels.propose_shorten(q0, *self.step)

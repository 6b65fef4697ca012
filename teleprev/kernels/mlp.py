"""Compiled (numba) kernels for CPN / CCN inference: the forward pass of G parallel MLPs, the CPN's
every-link-free decision, and the Corrector's CCN proposal with its shortened fractions, in one call.

A network comes packed by teleprev.noncollision.compiled.pack into three flat arrays:

    net_i (int64)    header [G, width_in, width_out, layers, joints, activation, noisy_or, outputs], then
                     the input index (G, width_in), per layer (weight offset, bias offset, in, out), and
                     which slots feed each output (CSR: outputs + 1 pointers, then slot numbers)
    net_w (float32)  the folded weights (G, in, out) and biases (G, out) of every layer (MLP._w, MLP._b)
    net_f (float64)  CCN: lower (n), upper (n), output_scale (n)

Arithmetic (what makes the answers the same bits every time, on every x86-64 CPU):

- The layers are float32 as in numpy, but the loop order is fixed: a unit's sum starts from its bias and
  adds input i's product in order i = 0, 1, ... (zero inputs, which add an exact zero, are skipped).
  The inner loop runs across output units, each its own sum, so the compiler vectorises it without
  reassociating anything. No fastmath: no reassociation and no fused multiply-add contraction. numpy's
  matmul goes to OpenBLAS, which picks its kernels (blocking, FMA) per CPU; these loops do not.
- A row's arithmetic never depends on the other rows of its batch, so a batch answers bit for bit as
  single calls do. Batches run four rows per pass over a layer's weights (_dense4), each
  weight loaded once for all of them; such a pass skips only the inputs that are zero in every one of its
  rows, so a row may add an exact zero product that alone it skips: no nonzero sum changes, and a zero
  sum's sign is not seen by anything after it (see _dense4). Other rows run alone (_forward1).
- exp is computed here (_exp: float64, range-reduced by halving, a Taylor polynomial and squaring: only
  + and *), not by the C library, whose expf/tanhf may differ between CPU variants and versions. It
  serves the SiLU / tanh activations (computed in float64, rounded to float32) and the CPN's decision.
- CPN decision: with noisy-or, p_link = 1 - prod_s sigmoid(-z_s) < t  <=>  prod_s (1 + exp(z_s)) <
  1 / (1 - t), the product in float64 over the link's slots in order; with identity, sum_s z_s <
  log(t / (1 - t)). This decides as numpy's float32 softplus sum does except within rounding of the
  threshold; every answer the Corrector returns is still checked exactly.

Compiled on the first call and cached on disk (cache=True); teleprev.noncollision.compiled.warm(), run by
scripts/setup.sh, fills the cache. All kernels are in this one file: numba invalidates a cached kernel
when its own source file changes, not when a kernel it calls in another file does.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

RELU, SILU, TANH = 0, 1, 2
HEADER = 8  # G, width_in, width_out, layers, joints, activation, noisy_or, outputs
BLOCK = 8  # rows per block in batches (passes of four rows over each layer, then one row at a time)
EXP_CLAMP = 88.0  # |x| clamped for exp: beyond it nothing these kernels decide changes


class Net(NamedTuple):
    """A network packed for the kernels (layout above)."""

    net_i: np.ndarray  # int64
    net_w: np.ndarray  # float32


class CcnStep(NamedTuple):
    """The Corrector's CCN step: the CCN, its limits and output scale, and the CPN's decision."""

    ccn_i: np.ndarray
    ccn_w: np.ndarray
    ccn_f: np.ndarray  # float64: lower, upper, output_scale
    cpn_i: np.ndarray
    cpn_w: np.ndarray
    bound: float  # the CPN's decision bound (see the module docstring)
    steps: int  # 2 ** the Corrector's shortening levels


@njit(cache=True, inline="always", error_model="numpy")
def _exp(x):
    """exp(x) in float64 for x clamped to [-88, 88], relative error below 1e-10: x / 1024, a degree-7
    Taylor polynomial, squared ten times. Only + and * (no library call): the same bits everywhere."""
    x = min(max(x, -EXP_CLAMP), EXP_CLAMP) * (1.0 / 1024.0)
    p = 1.0 + x * (
        1.0
        + x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0 + x * (1.0 / 720.0 + x * (1.0 / 5040.0))))))
    )
    for _ in range(10):
        p = p * p
    return p


@njit(cache=True, error_model="numpy")
def _layout(net_i):
    """Offsets into net_i: of the layer table, of the output pointers, of the output slot list."""
    g, win, n_layers, m = net_i[0], net_i[1], net_i[3], net_i[7]
    lay = HEADER + g * win
    ptr = lay + 4 * n_layers
    return lay, ptr, ptr + m + 1


@njit(cache=True, error_model="numpy")
def _dense(h, n_in, n_out, w, bias, nz, acc):
    """acc[:n_out] = bias + sum_i h[i] w[i, :] (float32), the terms added in order of i; zero inputs (which
    add an exact zero) skipped. Four inputs per pass over acc: the same additions in the same order as one
    at a time, with a quarter of the loads and stores of acc."""
    k = 0
    for i in range(n_in):  # the nonzero inputs, without a branch
        nz[k] = i
        k += h[i] != 0
    for o in range(n_out):
        acc[o] = bias[o]
    j = 0
    while j + 4 <= k:
        i0, i1, i2, i3 = nz[j], nz[j + 1], nz[j + 2], nz[j + 3]
        v0, v1, v2, v3 = h[i0], h[i1], h[i2], h[i3]
        w0 = w[i0 * n_out:(i0 + 1) * n_out]
        w1 = w[i1 * n_out:(i1 + 1) * n_out]
        w2 = w[i2 * n_out:(i2 + 1) * n_out]
        w3 = w[i3 * n_out:(i3 + 1) * n_out]
        for o in range(n_out):
            acc[o] = (((acc[o] + v0 * w0[o]) + v1 * w1[o]) + v2 * w2[o]) + v3 * w3[o]
        j += 4
    while j < k:
        i = nz[j]
        v = h[i]
        wi = w[i * n_out:(i + 1) * n_out]
        for o in range(n_out):
            acc[o] = acc[o] + v * wi[o]
        j += 1


@njit(cache=True, error_model="numpy")
def _dense4(h, n_in, n_out, w, bias, nz, acc):
    """_dense for four rows, h[0:4] into acc[0:4], two inputs per pass over the accumulators: each weight
    row loaded once for all four. Each row's sum still starts from its bias and adds input i's product in
    order of i; the inputs are those nonzero in any of the rows, so a row may add an exact zero product
    the one-row pass skips. That changes no nonzero value (x + 0 == x) and at most the sign of a zero sum,
    which nothing downstream tells apart (ReLU makes it +0; SiLU and tanh keep it a zero, skipped or added
    as a zero; the CPN's exp and the CCN's sum from +0.0 treat -0 as +0): the CPN's decisions and the
    CCN's proposals are the bits of one row at a time, and a raw output (slots) differs at most in the
    sign of an exact zero."""
    h0, h1, h2, h3 = h[0], h[1], h[2], h[3]
    k = 0
    for i in range(n_in):
        nz[k] = i
        k += (h0[i] != 0) | (h1[i] != 0) | (h2[i] != 0) | (h3[i] != 0)
    acc0, acc1, acc2, acc3 = acc[0], acc[1], acc[2], acc[3]
    for o in range(n_out):
        acc0[o] = bias[o]
        acc1[o] = bias[o]
        acc2[o] = bias[o]
        acc3[o] = bias[o]
    j = 0
    while j + 2 <= k:
        i0, i1 = nz[j], nz[j + 1]
        w0 = w[i0 * n_out:(i0 + 1) * n_out]
        w1 = w[i1 * n_out:(i1 + 1) * n_out]
        a0, a1, b0, b1 = h0[i0], h0[i1], h1[i0], h1[i1]
        c0, c1, d0, d1 = h2[i0], h2[i1], h3[i0], h3[i1]
        for o in range(n_out):
            x0, x1 = w0[o], w1[o]
            acc0[o] = (acc0[o] + a0 * x0) + a1 * x1
            acc1[o] = (acc1[o] + b0 * x0) + b1 * x1
            acc2[o] = (acc2[o] + c0 * x0) + c1 * x1
            acc3[o] = (acc3[o] + d0 * x0) + d1 * x1
        j += 2
    while j < k:
        i = nz[j]
        a0, b0, c0, d0 = h0[i], h1[i], h2[i], h3[i]
        wi = w[i * n_out:(i + 1) * n_out]
        for o in range(n_out):
            x0 = wi[o]
            acc0[o] = acc0[o] + a0 * x0
            acc1[o] = acc1[o] + b0 * x0
            acc2[o] = acc2[o] + c0 * x0
            acc3[o] = acc3[o] + d0 * x0
        j += 1


@njit(cache=True, inline="always", error_model="numpy")
def _activate(acc, h, n_out, act):
    """h[:n_out] = the hidden activation of acc[:n_out] (float32)."""
    if act == RELU:
        for o in range(n_out):
            v = acc[o]
            h[o] = v if v > 0 else np.float32(0.0)
    elif act == SILU:  # z sigmoid(z) = z / (1 + exp(-z))
        for o in range(n_out):
            z = np.float64(acc[o])
            h[o] = np.float32(z / (1.0 + _exp(-z)))
    else:  # tanh(z) = (1 - exp(-2z)) / (1 + exp(-2z))
        for o in range(n_out):
            e = _exp(-2.0 * np.float64(acc[o]))
            h[o] = np.float32((1.0 - e) / (1.0 + e))


@njit(cache=True, inline="always", error_model="numpy")
def _widest(net_i):
    """The widest activation of a network: its input or one of its layers' outputs."""
    lay = _layout(net_i)[0]
    widest = net_i[1]
    for layer in range(net_i[3]):
        widest = max(widest, net_i[lay + 4 * layer + 3])
    return widest


@njit(cache=True, inline="always", error_model="numpy")
def _layer(net_i, lay, layer, g):
    """Layer `layer` of network g: (inputs, outputs, offset of its weights, offset of its biases in net_w)."""
    t = lay + 4 * layer
    n_in, n_out = net_i[t + 2], net_i[t + 3]
    return n_in, n_out, net_i[t] + g * n_in * n_out, net_i[t + 1] + g * n_out


@njit(cache=True, error_model="numpy")
def _forward(x, r0, nb, net_i, net_w, slots):
    """Raw outputs of rows r0 .. r0 + nb of x (float64 (R, n)) into slots[:nb] (float32 (>= nb, G * width_out)),
    four rows per pass over each layer (_dense4) while four are left, then each row alone (_forward1). A
    row's outputs do not depend on what else is in the batch (see _dense4)."""
    g_count, win, wout, n_layers, act = net_i[0], net_i[1], net_i[2], net_i[3], net_i[5]
    lay = _layout(net_i)[0]
    widest = _widest(net_i)
    h = np.zeros((4, widest), np.float32)
    acc = np.empty((4, widest), np.float32)
    nz = np.empty(widest, np.int64)
    r = 0
    while r + 4 <= nb:
        for g in range(g_count):
            for i in range(win):
                c = net_i[HEADER + g * win + i]
                for k in range(4):
                    h[k, i] = np.float32(x[r0 + r + k, c])
            for layer in range(n_layers):
                n_in, n_out, w0, b0 = _layer(net_i, lay, layer, g)
                _dense4(h, n_in, n_out, net_w[w0:w0 + n_in * n_out], net_w[b0:b0 + n_out], nz, acc)
                if layer == n_layers - 1:
                    for k in range(4):
                        for o in range(n_out):
                            slots[r + k, g * wout + o] = acc[k, o]
                else:
                    for k in range(4):
                        _activate(acc[k], h[k], n_out, act)
        r += 4
    for k in range(r, nb):
        _forward1(x, r0 + k, net_i, net_w, slots[k:k + 1], h[0], acc[0], nz)


@njit(cache=True, error_model="numpy")
def _forward1(x, row, net_i, net_w, slots, h, acc, nz):
    """Raw outputs of row `row` of x (float64 (R, n)) into slots[0], one row alone; h, acc, nz: scratch of
    the network's widest activation (every entry is written before it is read)."""
    g_count, win, wout, n_layers, act = net_i[0], net_i[1], net_i[2], net_i[3], net_i[5]
    lay = _layout(net_i)[0]
    for g in range(g_count):
        for i in range(win):
            h[i] = np.float32(x[row, net_i[HEADER + g * win + i]])
        for layer in range(n_layers):
            n_in, n_out, w0, b0 = _layer(net_i, lay, layer, g)
            _dense(h, n_in, n_out, net_w[w0:w0 + n_in * n_out], net_w[b0:b0 + n_out], nz, acc)
            if layer == n_layers - 1:
                for o in range(n_out):
                    slots[0, g * wout + o] = acc[o]
            else:
                _activate(acc, h, n_out, act)


@njit(cache=True, error_model="numpy")
def _free_rows(slots, nb, net_i, bound, free, r0):
    """free[r0 + r] for the rows' raw outputs: every output (link) below the threshold (see the module doc)."""
    _, ptr, lst = _layout(net_i)
    noisy_or, m = net_i[6], net_i[7]
    for r in range(nb):
        ok = True
        for k in range(m):
            if noisy_or:
                p = 1.0
                for j in range(net_i[ptr + k], net_i[ptr + k + 1]):
                    p *= 1.0 + _exp(np.float64(slots[r, net_i[lst + j]]))
            else:
                p = 0.0
                for j in range(net_i[ptr + k], net_i[ptr + k + 1]):
                    p += np.float64(slots[r, net_i[lst + j]])
            if not p < bound:
                ok = False
                break
        free[r0 + r] = ok


@njit(cache=True, error_model="numpy")
def _propose_row(q, slots_row, net_i, net_f, out):
    """The CCN's proposal clip(q + output_scale * delta) for one configuration, delta from its raw outputs."""
    _, ptr, lst = _layout(net_i)
    n = net_i[4]
    for k in range(n):
        d = 0.0
        for j in range(net_i[ptr + k], net_i[ptr + k + 1]):
            d += np.float64(slots_row[net_i[lst + j]])
        v = q[k] + net_f[2 * n + k] * d
        out[k] = min(max(v, net_f[k]), net_f[n + k])


@njit(cache=True, error_model="numpy")
def slots(x, net_i, net_w):
    """Raw outputs (R, G * width_out) float32 of configurations x (R, n) float64."""
    rows = x.shape[0]
    out = np.empty((rows, net_i[0] * net_i[2]), np.float32)
    for r0 in range(0, rows, BLOCK):
        nb = min(BLOCK, rows - r0)
        _forward(x, r0, nb, net_i, net_w, out[r0:r0 + nb])
    return out


@njit(cache=True, error_model="numpy")
def predicts_free(x, net_i, net_w, bound):
    """(R,) bool: the CPN predicts every link free, for configurations x (R, n) float64."""
    rows = x.shape[0]
    free = np.empty(rows, np.bool_)
    buf = np.empty((BLOCK, net_i[0] * net_i[2]), np.float32)
    for r0 in range(0, rows, BLOCK):
        nb = min(BLOCK, rows - r0)
        _forward(x, r0, nb, net_i, net_w, buf)
        _free_rows(buf, nb, net_i, bound, free, r0)
    return free


@njit(cache=True, error_model="numpy")
def propose(x, net_i, net_w, net_f):
    """The CCN's proposals (R, n) for configurations x (R, n) float64 (within the limits)."""
    rows, n = x.shape
    out = np.empty((rows, n))
    buf = np.empty((BLOCK, net_i[0] * net_i[2]), np.float32)
    for r0 in range(0, rows, BLOCK):
        nb = min(BLOCK, rows - r0)
        _forward(x, r0, nb, net_i, net_w, buf)
        for r in range(nb):
            _propose_row(x[r0 + r], buf[r], net_i, net_f, out[r0 + r])
    return out


@njit(cache=True, error_model="numpy")
def propose_shorten(q0, ccn_i, ccn_w, ccn_f, cpn_i, cpn_w, bound, steps):
    """Corrector's CCN step for configurations q0 (R, n) float64 (within the limits, colliding), in one call:

    proposal (R, n): the CCN's;  shorter (R, n): q0 + (hi / steps) (proposal - q0);  hi (R,): the
    fraction (in 1 / steps) that Corrector._shortest_predicted_free's bisection picks, `steps` where the
    CPN predicts none of the points it tries free (then `shorter` is the proposal's row, unused).
    The bisection scores the point of each level as it goes (log2(steps) CPN rows, not steps - 1), one
    level of every row at a time so that the CPN scores the rows' points in blocks; a row's answer does
    not depend on the others, so a batch answers as single calls do.
    """
    rows, n = q0.shape
    proposal = propose(q0, ccn_i, ccn_w, ccn_f)
    shorter = proposal.copy()
    lo = np.zeros(rows, np.int64)
    hi = np.full(rows, steps, np.int64)
    active = np.empty(rows, np.int64)  # the rows still bisecting, this level
    points = np.empty((rows, n))
    free = np.empty(rows, np.bool_)
    buf = np.empty((BLOCK, cpn_i[0] * cpn_i[2]), np.float32)
    while True:  # one level of every row's bisection per pass, its points scored in blocks
        m = 0
        for r in range(rows):
            if hi[r] - lo[r] > 1:
                f = ((lo[r] + hi[r]) // 2) / steps
                for j in range(n):
                    points[m, j] = q0[r, j] + f * (proposal[r, j] - q0[r, j])
                active[m] = r
                m += 1
        if m == 0:
            break
        for r0 in range(0, m, BLOCK):
            nb = min(BLOCK, m - r0)
            _forward(points, r0, nb, cpn_i, cpn_w, buf)
            _free_rows(buf, nb, cpn_i, bound, free, r0)
        for k in range(m):
            r = active[k]
            mid = (lo[r] + hi[r]) // 2
            if free[k]:
                hi[r] = mid
                shorter[r] = points[k]
            else:
                lo[r] = mid
    return proposal, shorter, hi


# Each kernel's parameters, a table standing for its fields in order (tests/kernels/test_tables.py).
SIGNATURES = {
    "slots": ("x", Net),
    "predicts_free": ("x", Net, "bound"),
    "propose": ("x", Net, "net_f"),
    "propose_shorten": ("q0", CcnStep),
}

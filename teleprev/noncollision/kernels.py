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
- A row's arithmetic never depends on the other rows of its batch (rows are processed in blocks only
  to reuse the weights they stream), so a batch answers bit for bit as single calls do.
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

import numpy as np
from numba import njit

RELU, SILU, TANH = 0, 1, 2
HEADER = 8  # G, width_in, width_out, layers, joints, activation, noisy_or, outputs
BLOCK = 8  # rows per block in batches (they share each weight row while it is in cache)
EXP_CLAMP = 88.0  # |x| clamped for exp: beyond it nothing these kernels decide changes


@njit(cache=True, inline="always", error_model="numpy")
def _exp(x):
    """exp(x) in float64 for x clamped to [-88, 88], relative error below 1e-10: x / 1024, a degree-7
    Taylor polynomial, squared ten times. Only + and * (no library call): the same bits everywhere."""
    x = min(max(x, -EXP_CLAMP), EXP_CLAMP) * (1.0 / 1024.0)
    p = 1.0 + x * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0 + x * (1.0 / 720.0 + x * (1.0 / 5040.0)))))))
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
def _forward(x, r0, nb, net_i, net_w, slots):
    """Raw outputs of rows r0 .. r0 + nb of x (float64 (R, n)) into slots[:nb] (float32 (>= nb, G * width_out)),
    one row at a time: a row's arithmetic is the same whatever else is in the batch."""
    g_count, win, wout, n_layers, act = net_i[0], net_i[1], net_i[2], net_i[3], net_i[5]
    lay = HEADER + g_count * win
    widest = win
    for layer in range(n_layers):
        widest = max(widest, net_i[lay + 4 * layer + 3])
    h = np.zeros(widest, np.float32)
    acc = np.empty(widest, np.float32)
    nz = np.empty(widest, np.int64)
    for r in range(nb):
        for g in range(g_count):
            for i in range(win):
                h[i] = np.float32(x[r0 + r, net_i[HEADER + g * win + i]])
            for layer in range(n_layers):
                t = lay + 4 * layer
                n_in, n_out = net_i[t + 2], net_i[t + 3]
                w0 = net_i[t] + g * n_in * n_out
                b0 = net_i[t + 1] + g * n_out
                _dense(h, n_in, n_out, net_w[w0:w0 + n_in * n_out], net_w[b0:b0 + n_out], nz, acc)
                if layer == n_layers - 1:
                    for o in range(n_out):
                        slots[r, g * wout + o] = acc[o]
                elif act == RELU:
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
    The bisection scores the point of each level as it goes (log2(steps) CPN rows, not steps - 1); a
    row's answer does not depend on the others, so a batch answers as single calls do.
    """
    rows, n = q0.shape
    proposal = propose(q0, ccn_i, ccn_w, ccn_f)
    shorter = np.empty((rows, n))
    hi_out = np.empty(rows, np.int64)
    point = np.empty((1, n))
    buf = np.empty((1, cpn_i[0] * cpn_i[2]), np.float32)
    free = np.zeros(1, np.bool_)
    for r in range(rows):
        shorter[r] = proposal[r]
        lo, hi = 0, steps
        while hi - lo > 1:
            mid = (lo + hi) // 2
            f = mid / steps
            for j in range(n):
                point[0, j] = q0[r, j] + f * (proposal[r, j] - q0[r, j])
            _forward(point, 0, 1, cpn_i, cpn_w, buf)
            _free_rows(buf, 1, cpn_i, bound, free, 0)
            if free[0]:
                hi = mid
                shorter[r] = point[0]
            else:
                lo = mid
        hi_out[r] = hi
    return proposal, shorter, hi_out

"""The Corrector's answer for one configuration in one call (the live step's case): the exact check, then
where it collides the CCN step and the exact checks of its shortened and full proposals, in the order
Corrector.correct makes them. The answers where FCL or the previous output must decide are left to the
Corrector's own path (teleprev.noncollision.corrector).
"""

from __future__ import annotations

from numba import njit

from teleprev.kernels.collision import BoxTable, Margins, check_margins, collides_margins
from teleprev.kernels.fk import FkTable
from teleprev.kernels.mlp import CcnStep, propose_shorten

# correct_one's answers: the configuration is free (out = q0), the shortened or the full CCN proposal is
# (out = it), or the kernel cannot decide alone (a configuration within the margin of touching, for FCL;
# both proposals collide, for the fallback, which needs the previous output)
ONE_UNTOUCHED, ONE_SHORTENED, ONE_PROPOSAL, ONE_UNDECIDED = 0, 1, 2, 3


@njit(cache=True)
def _deviation(out, q_in):
    """max |out - q_in| (what np.abs(out - q_in).max() gives: a maximum is exact in any order)."""
    d = 0.0
    for k in range(q_in.shape[0]):
        d = max(d, abs(out[k] - q_in[k]))
    return d


@njit(cache=True)
def correct_one(q_in, q0, link_int, link_num, link_terms, shape_link, shape_local, shape_size, links, spheres,
                pairs, loose, tight, ccn_i, ccn_w, ccn_f, cpn_i, cpn_w, bound, steps, labels, index, out):
    """(answer, colliding pairs, deviation) for q_in, clipped to the limits as q0 (n,): ONE_* above, the
    count of q0's colliding pairs (their indices in index[:count], their links in labels, zeros on the way
    in) and max |out - q_in| for the answer left in out (n,)."""
    count = check_margins(q0, link_int, link_num, link_terms, shape_link, shape_local, shape_size, links, spheres,
                          pairs, loose, tight, False, labels, index)
    if count < 0:
        return ONE_UNDECIDED, count, 0.0
    if count == 0:
        out[:] = q0
        return ONE_UNTOUCHED, 0, _deviation(out, q_in)
    rows = q0.reshape((1, q0.shape[0]))
    proposal, shorter, hi = propose_shorten(rows, ccn_i, ccn_w, ccn_f, cpn_i, cpn_w, bound, steps)
    if hi[0] != steps:
        state = collides_margins(shorter[0], link_int, link_num, link_terms, shape_link, shape_local, shape_size,
                                 links, spheres, pairs, loose, tight)
        if state < 0:
            return ONE_UNDECIDED, count, 0.0
        if state == 0:
            out[:] = shorter[0]
            return ONE_SHORTENED, count, _deviation(out, q_in)
    state = collides_margins(proposal[0], link_int, link_num, link_terms, shape_link, shape_local, shape_size,
                             links, spheres, pairs, loose, tight)
    if state != 0:
        return ONE_UNDECIDED, count, 0.0
    out[:] = proposal[0]
    return ONE_PROPOSAL, count, _deviation(out, q_in)


SIGNATURES = {
    "correct_one": ("q_in", "q0", FkTable, BoxTable, Margins, CcnStep, "labels", "index", "out"),
}

"""Step 2 of the S-curve planner (planning.scurve_plan): the key points of a grid, their kinds
and nominal speeds, the eroded limit and each segment's cap. A compiled kernel, written once in
numba's subset."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.plan import (
    KIND_CORNER,
    KIND_CUSP,
    KIND_END,
    KIND_FEED,
    KIND_PEAK,
    KIND_SHOULDER,
)


@jit
def key_points(kappa, raw_limit, fcap, stop_index, stop_cos, peak_index, feed_nodes, kappa0,
                feed_cap, shoulder_nodes):
    """Steps 2 and 5's limit: the eroded limit (M,), key nodes, kinds and nominal speeds (K,),
    segment caps (K-1,) and the number of peaks with kappa >= kappa0.

    Stops (grid step 3: corners, and cusps or reversals where the tangent turns back, cos < 0;
    kappa infinite inside the curve) are passed at rest. The eroded
    limit is min(raw[i-1], raw[i], raw[i+1]) per node, except that a stop (limit 0) does not
    spread to its neighbours (beside a corner the curvature is finite): it borrows their limits
    while eroding. Key kinds: the ends, then feed changes, peaks with kappa >= kappa0 and stops
    (a later kind wins at a node), and the shoulders `plan_curve` adds; nominal speed 0 at the
    ends and stops, the limit at the others, and at a feed change the lower of the two feeds.
    A segment's cap is the lowest feed over its nodes, from its first key node to the next one
    (the last node included).
    """
    size = kappa.size
    last = size - 1
    # loops rather than np.full, np.flatnonzero, index arrays and np.searchsorted: each of
    # those compiles numba's own implementation, together a second of the first run
    kind = np.empty(size, dtype=np.int64)
    for n in range(size):
        kind[n] = -1
    kind[0] = KIND_END
    kind[last] = KIND_END
    for n in feed_nodes:
        if 0 < n < last:
            kind[n] = KIND_FEED
    for n in shoulder_nodes:
        if 0 < n < last:
            kind[n] = KIND_SHOULDER
    n_peaks = 0
    for n in peak_index:
        if kappa[n] >= kappa0:
            n_peaks += 1
            if 0 < n < last:
                kind[n] = KIND_PEAK
    for q in range(stop_index.size):
        n = stop_index[q]
        if 0 < n < last:
            kind[n] = KIND_CUSP if stop_cos[q] < 0.0 else KIND_CORNER
    for n in range(1, last):
        if math.isinf(kappa[n]) and kind[n] != KIND_CUSP:
            kind[n] = KIND_CORNER
    borrowed = raw_limit.copy()
    for n in range(1, last):
        if kind[n] == KIND_CORNER or kind[n] == KIND_CUSP:
            borrowed[n] = min(raw_limit[n - 1], raw_limit[n + 1])
    limit = borrowed.copy()
    for n in range(size):
        if n > 0:
            limit[n] = min(limit[n], borrowed[n - 1])
        if n < last:
            limit[n] = min(limit[n], borrowed[n + 1])
        if kind[n] == KIND_CORNER or kind[n] == KIND_CUSP:
            limit[n] = 0.0
    n_keys = 0
    for n in range(size):
        if kind[n] >= 0:
            n_keys += 1
    key_node = np.empty(n_keys, dtype=np.int64)
    key_kind = np.empty(n_keys, dtype=np.int64)
    nominal = np.empty(n_keys)
    keys_before = np.empty(size, dtype=np.int64)  # per node, the key nodes below it
    k = 0
    for n in range(size):
        keys_before[n] = k
        if kind[n] >= 0:
            key_node[k] = n
            key_kind[k] = kind[n]
            nominal[k] = limit[n]
            k += 1
    for k in range(key_node.size):
        if key_kind[k] == KIND_END or key_kind[k] == KIND_CORNER or key_kind[k] == KIND_CUSP:
            nominal[k] = 0.0
    for n in feed_nodes:
        k = keys_before[n] if n < size else n_keys
        nominal[k] = min(nominal[k], fcap[max(n - 1, 0)], fcap[n])
    cap = np.empty(key_node.size - 1)
    for k in range(cap.size):
        cap[k] = feed_cap
    seg = 0
    for n in range(size):
        if seg + 1 < cap.size and n >= key_node[seg + 1]:
            seg += 1
        cap[seg] = min(cap[seg], fcap[n])
    return limit, key_node, key_kind, nominal, cap, n_peaks

"""Euler trail by Hierholzer's algorithm on edge arrays (O(V + E), iterative)."""

from __future__ import annotations

import numpy as np

from planners.errors import InternalError


def euler_trail(n: int, eu: np.ndarray, ev: np.ndarray, start: int) -> tuple[list[int], list[bool]]:
    """Traverse every edge ``j`` (``eu[j]``–``ev[j]``, self-loops and repeats allowed) once.

    Hierholzer (1873): walk unused edges until stuck, back up and splice sub-tours.  The
    graph must be connected on its edges and have 0 odd vertices (then the trail is a
    circuit through ``start``) or exactly 2 with ``start`` one of them (the trail ends at
    the other).  Returns the edge order and, per step, ``True`` when edge ``j`` is driven
    ``eu[j] → ev[j]``.  Adjacency is ordered by edge id, so the result is deterministic.
    """
    m = int(eu.size)
    ends = np.concatenate((eu, ev))
    order = np.argsort(ends, kind="stable")
    indptr = np.searchsorted(ends[order], np.arange(n + 1)).tolist()
    slot_edge = (order % m).tolist() if m else []
    slot_other = np.concatenate((ev, eu))[order].tolist()
    ptr = indptr[:-1]
    first_end = eu.tolist()
    used = bytearray(m)
    # Plain lists: this loop runs once per traversed edge, so Python-level speed matters.
    vstack = [start]
    estack: list[tuple[int, bool]] = []
    out_e: list[int] = []
    out_f: list[bool] = []
    while vstack:
        x = vstack[-1]
        p, stop = ptr[x], indptr[x + 1]
        while p < stop and used[slot_edge[p]]:
            p += 1
        if p == stop:
            ptr[x] = p
            vstack.pop()
            if estack:
                j, fwd = estack.pop()
                out_e.append(j)
                out_f.append(fwd)
            continue
        ptr[x] = p + 1
        j = slot_edge[p]
        used[j] = 1
        y = slot_other[p]
        # Driven x → y; eu[j] == x means forward (a self-loop reads as forward).
        estack.append((j, first_end[j] == x))
        vstack.append(y)
    if len(out_e) != m:
        raise InternalError(
            f"Euler trail covered {len(out_e)} of {m} edges: the multigraph is not connected "
            "or has the wrong odd vertices (internal error)"
        )
    out_e.reverse()
    out_f.reverse()
    return out_e, out_f

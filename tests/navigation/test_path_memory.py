"""The path stage's memory stays bounded on a body-sized turn search.

A field scan's path stage was killed after allocating 22.8 GB in
``DiffDrivePlanner.turn_point → poses_valid → BoundarySet.contains``: every
turning-point candidate (a 5 mm grid within the turn radius × 4 headings)
had its turn poses built, checked by Alg. 6 and then by the exact
rectangle test (one shapely polygon per passing pose) in one call.  Here the
same chain (the pipeline's validity: Alg. 6 on the footprint points, then
the rectangle on the steel union) runs on a 3 × 3 m plate with the ARA's
mobile body footprint and a 0.5 m turn radius: 31k grid points × 4
headings, ~8M turn poses.  Measured on this call before the fix (one
validity call over every candidate's turn poses, then a shapely rectangle
for every pose that passed): 3.6 GB max RSS in 3.5 min without a limit,
``MemoryError`` under the 2 GiB limit below; after it (candidates cheapest
first in bounded batches, stopping at the first way that passes): 133 MB in
2.2 s, the same way.

The check runs in a child process under ``RLIMIT_AS`` = 2 GiB, set before
numpy, scipy, shapely and OMPL are imported; those imports reserve about
0.36 GB of address space (VmSize after importing ``planners.navigation``,
measured), so the planning itself has ~1.6 GB.
"""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
import textwrap

LIMIT_BYTES = 2 << 30

CHILD = textwrap.dedent(
    f"""
    import resource
    resource.setrlimit(resource.RLIMIT_AS, ({LIMIT_BYTES}, {LIMIT_BYTES}))
    import json
    import numpy as np
    from planners.navigation.pibc import (
        BoundarySet, footprint_points, poses_valid, rectangles_on_steel, steel_union,
    )
    from planners.navigation.rrt import DiffDrivePlanner

    # the ARA body ([mobile_footprint]) grown by the pipeline's 1 mm margin
    length, width, cx = 0.682, 0.162, -0.25
    plate = np.array([[-1.5, -1.5], [1.5, -1.5], [1.5, 1.5], [-1.5, 1.5]])
    bset = BoundarySet([np.zeros(2)], [plate])
    steel = steel_union([plate])
    foot = footprint_points(length, width, center_x_m=cx, spacing_m=0.04)

    def valid(q):
        # the pipeline's validity (pipeline._edge_paths): Alg. 6, then the rectangle
        ok = poses_valid(q, foot, bset, n_centres=1)
        if ok.any():
            ok[ok] = rectangles_on_steel(q[ok], steel, length, width, center_x_m=cx)
        return ok

    planner = DiffDrivePlanner(valid, yaw_radius_m=0.34, turn_resolution_rad=0.05)
    start = np.array([0.8, 0.0, np.pi])
    goal = np.array([0.0, 0.8, np.pi / 2])
    way = planner.turn_point(start, goal, np.zeros(2), radius_m=0.5)
    print(json.dumps(None if way is None else np.array(way).tolist()))
    """
)


def test_turn_point_search_within_two_gib() -> None:
    proc = subprocess.run(
        [sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=240
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    way = json.loads(proc.stdout.strip().splitlines()[-1])
    assert way is not None
    # start → turning point (heading in) → turn in place → goal (heading out):
    # the cheapest candidate on the plate, the same as the one-call search gave
    assert way[0] == [0.8, 0.0, 3.141592653589793]
    assert way[-1] == [0.0, 0.8, 1.5707963267948966]
    turns = [(a, b) for a, b in itertools.pairwise(way) if a[:2] == b[:2]]
    inner = [(a, b) for a, b in turns if a[:2] not in ([0.8, 0.0], [0.0, 0.8])]
    assert len(inner) == 1
    p_in, p_out = inner[0]
    assert p_in[0] ** 2 + p_in[1] ** 2 <= 0.5**2  # within the turn radius
    assert p_in[2] != p_out[2]

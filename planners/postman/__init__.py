"""Chinese-postman building blocks behind :func:`planners.vocpp.plan_route`.

- :mod:`.graph_arrays` — array view of a networkx (multi)graph plus input validation;
- :mod:`.tjoin` — minimum-weight T-join (Edmonds & Johnson 1973) on the sparse graph with
  PyMatching's sparse blossom (Higgott & Gidney), made exact by integer scaling;
- :mod:`.euler` — Hierholzer's Euler trail on arrays;
- :mod:`.thesis` — the seed's Algorithm 5 (VOCPP) as printed, for comparison.
"""

from __future__ import annotations

from planners.postman.euler import euler_trail
from planners.postman.graph_arrays import EdgeArrays, check_connected, edge_arrays, simple_edges
from planners.postman.thesis import thesis_augmentation
from planners.postman.tjoin import TJoin, min_t_join

__all__ = [
    "EdgeArrays",
    "TJoin",
    "check_connected",
    "edge_arrays",
    "euler_trail",
    "min_t_join",
    "simple_edges",
    "thesis_augmentation",
]

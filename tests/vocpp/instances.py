"""Readers for the shared real instances: CARPLIB ``.dat`` graphs and postman_problems CSVs.

Data lives in ``../shared/data`` (read in place, never copied).  :data:`DATA` is ``None``
when that folder is absent so tests can skip with a clear reason.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

import networkx as nx

_ROOT = Path(__file__).resolve().parents[2]
_CANDIDATE = _ROOT.parent / "shared" / "data"
DATA: Path | None = _CANDIDATE if (_CANDIDATE / "carp").is_dir() else None
SKIP_REASON = f"shared data folder {_CANDIDATE} is absent (CARP/postman instances not available)"

_EDGE = re.compile(r"^\s*\(\s*(\d+)\s*,\s*(\d+)\s*\)\s*coste\s+(\S+)(?:\s+demanda\s+(\S+))?")
_HEADER = re.compile(r"^\s*([A-Z_]+)\s*:\s*(.*?)\s*$")


@dataclass(frozen=True)
class CarpInstance:
    """A CARPLIB instance as a MultiGraph (edge attrs ``weight``, ``demand``, ``required``)."""

    name: str
    graph: nx.MultiGraph
    depot: int
    header: dict[str, str]


def read_carp(path: str | Path) -> CarpInstance:
    """Parse a CARPLIB ``.dat`` file (Spanish keywords, ``( u, v) coste C demanda D`` lines).

    Every listed edge — required (``LISTA_ARISTAS_REQ``) and not required
    (``LISTA_ARISTAS_NOREQ``) — becomes one MultiGraph edge, so parallel edges survive;
    the Chinese postman covers them all.  ``DEPOSITO : n`` is the depot.  Vertices
    ``1..VERTICES`` are all added, in order, even if some have no edge.
    """
    path = Path(path)
    header: dict[str, str] = {}
    edges: list[tuple[int, int, float, float | None, bool]] = []
    required = True
    for line in path.read_text(encoding="latin-1").splitlines():
        if "LISTA_ARISTAS_NOREQ" in line:
            required = False
            continue
        if "LISTA_ARISTAS_REQ" in line:
            required = True
            continue
        em = _EDGE.match(line)
        if em:
            demand = float(em.group(4)) if em.group(4) is not None else None
            cost = float(em.group(3))
            edges.append((int(em.group(1)), int(em.group(2)), cost, demand, required))
            continue
        hm = _HEADER.match(line)
        if hm:
            header[hm.group(1)] = hm.group(2)
    if "DEPOSITO" not in header:
        raise ValueError(f"{path}: no 'DEPOSITO : n' line")
    g = nx.MultiGraph(name=header.get("NOMBRE", path.stem))
    g.add_nodes_from(range(1, int(header.get("VERTICES", "0")) + 1))
    for a, b, c, d, req in edges:
        g.add_edge(a, b, weight=c, demand=d, required=req)
    n_listed = int(header.get("ARISTAS_REQ", "0")) + int(header.get("ARISTAS_NOREQ", "0"))
    if n_listed and n_listed != len(edges):
        raise ValueError(f"{path}: header lists {n_listed} edges, parsed {len(edges)}")
    return CarpInstance(name=path.stem, graph=g, depot=int(header["DEPOSITO"]), header=header)


def carp_paths() -> list[Path]:
    """All ``.dat`` files of the shared CARP folder, sorted by name (empty if absent)."""
    return sorted((DATA / "carp").glob("*.dat")) if DATA is not None else []


def read_postman_edgelist(
    path: str | Path, weight: str = "distance", *, required_only: bool = False
) -> nx.MultiGraph:
    """Read a postman_problems edge list CSV (``node1,node2,<attrs>``) into a MultiGraph.

    Numeric columns become floats; ``required_only`` keeps rows whose ``required`` column
    is 1 (Sleeping Giant: the 121 trail edges; the other 12 rows are roads).
    """
    g = nx.MultiGraph()
    with open(path, newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            row = {k.strip(): (v.strip() if isinstance(v, str) else v) for k, v in row.items()}
            if required_only and row.get("required", "1") not in ("1", "1.0"):
                continue
            attrs: dict[str, object] = {}
            for k, v in row.items():
                if k in ("node1", "node2"):
                    continue
                try:
                    attrs[k] = float(v)
                except (TypeError, ValueError):
                    attrs[k] = v
            if weight not in attrs:
                raise ValueError(f"{path}: row {row} has no {weight!r} column")
            g.add_edge(row["node1"], row["node2"], **attrs)
    return g

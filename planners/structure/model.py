"""The 3D structure model a field scan is turned into (DESIGN §5 addition).

:func:`planners.structure.model_structure` returns a :class:`StructureModel`:
steel members (centroid line, section profile, depth/width, drivable faces),
the joints where members meet, the member graph (nodes = joints and free
member ends, edges = member spans) and a member label per input point.
Every coordinate is in metres in the frame of the input points.

Faces use the form of :class:`planners.blasting.Surface` (plane origin and
unit normal, in-plane x axis, boundary polygon in the plane's 2D frame) so
any face can be handed to the blasting planner via :meth:`Face.surface`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import networkx as nx
import numpy as np

if TYPE_CHECKING:
    from planners.blasting.surface import Surface
    from planners.structure.surfaces import PlanarSurface

#: Section profiles a member can be given.
PROFILES: tuple[str, ...] = ("I", "channel", "angle", "tee", "box", "tube", "plate", "unknown")
#: What a face is on its member.
FACE_KINDS: tuple[str, ...] = ("flange", "web", "side", "plate")


@dataclass
class Face:
    """A planar surface of a member the robot could drive on or inspect.

    The plane passes through ``origin`` with unit ``normal`` (pointing out of
    the steel); ``x_axis`` is a unit vector in the plane (``y = normal ×
    x_axis``) and ``boundary`` the (K, 2) polygon in that 2D frame, metres.
    """

    id: int
    member: int
    kind: str
    origin: np.ndarray
    normal: np.ndarray
    x_axis: np.ndarray
    boundary: np.ndarray
    area_m2: float
    n_points: int

    @property
    def y_axis(self) -> np.ndarray:
        return np.cross(self.normal, self.x_axis)

    def to_world(self, uv: np.ndarray) -> np.ndarray:
        """(…, 2) in-plane coordinates → (…, 3) points."""
        p = np.asarray(uv, float)
        return self.origin + p[..., :1] * self.x_axis + p[..., 1:2] * self.y_axis

    def outline(self) -> np.ndarray:
        """(K, 3) boundary polygon in the input frame."""
        return self.to_world(self.boundary)

    def surface(self) -> Surface:
        """This face as a :class:`planners.blasting.Surface` (same plane and boundary)."""
        from planners.blasting.surface import Surface

        return Surface(
            origin=self.origin.copy(),
            normal=self.normal.copy(),
            boundary=self.boundary.copy(),
            x_axis=self.x_axis.copy(),
        )


@dataclass
class Member:
    """One steel member: ``axis`` the (2, 3) end points of its centroid line."""

    id: int
    axis: np.ndarray
    profile: str
    depth_m: float
    width_m: float
    faces: list[Face] = field(default_factory=list)
    n_points: int = 0
    #: how many occlusion fragments were joined into this member
    fragments: int = 1

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(self.axis[1] - self.axis[0]))

    @property
    def direction(self) -> np.ndarray:
        d = self.axis[1] - self.axis[0]
        n = float(np.linalg.norm(d))
        return d / n if n > 0 else d


@dataclass
class Joint:
    """Where members meet: ``pos`` (3,) and the ids of the members meeting there."""

    id: int
    pos: np.ndarray
    members: tuple[int, ...]


@dataclass
class StructureModel:
    """Result of :func:`planners.structure.model_structure`.

    ``graph`` is an undirected networkx ``MultiGraph``: nodes are ints with
    ``pos`` (3,), ``kind`` (``"joint"`` or ``"end"``) and, for joints,
    ``joint`` (the :class:`Joint` id); edges are member spans between
    consecutive nodes along a member with ``member`` (id) and ``weight``
    (length, m).  ``labels`` (N,) gives the member id of each input point or
    −1 (clutter, ground, surfaces, unassigned).  ``spacing_m`` is the measured point
    spacing the defaults were derived from; ``timings_s`` the seconds per stage.
    """

    members: list[Member]
    joints: list[Joint]
    graph: nx.MultiGraph
    labels: np.ndarray
    spacing_m: float
    timings_s: dict[str, float] = field(default_factory=dict)
    #: parameters actually used (after deriving defaults from the spacing)
    params: dict[str, float] = field(default_factory=dict)
    #: large planes that are not members (deck soffits, slabs, walls,
    #: ground; :mod:`planners.structure.surfaces`): their points are
    #: labelled −1 and were left out of the member search
    surfaces: list[PlanarSurface] = field(default_factory=list)

    @property
    def faces(self) -> list[Face]:
        return [f for m in self.members for f in m.faces]

    def profile_counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for m in self.members:
            out[m.profile] = out.get(m.profile, 0) + 1
        return out

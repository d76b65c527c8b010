"""Typed exceptions raised by every planner.

All are ``ValueError`` subclasses so a caller that only knows the standard
library still catches them; the REST layer maps :class:`PlannerError` to
HTTP 422 with the message as ``detail``.  Messages name the bad input and say
what would be accepted instead.

Planner modules add their own subclasses here (append only; keep one short
docstring each).
"""

from __future__ import annotations


class PlannerError(ValueError):
    """Base class: the request cannot be planned as given."""


class InvalidInputError(PlannerError):
    """An argument has the wrong shape, type, unit range or non-finite values."""


class InfeasibleError(PlannerError):
    """The input is well formed but no plan satisfies the constraints."""


class UnknownVertexError(InvalidInputError):
    """A start/end vertex is not in the graph."""


class DisconnectedGraphError(InfeasibleError):
    """The edges to cover do not lie in one connected component."""


class EmptyInputError(InvalidInputError):
    """A cloud, graph or polygon has nothing in it."""


class UnreachableError(InfeasibleError):
    """A target pose lies outside the robot's workspace or joint limits."""


class CancelledError(PlannerError):
    """The caller asked the planner to stop (raised from a progress callback)."""


class InvalidWeightError(InvalidInputError):
    """An edge weight is missing, non-numeric, negative or not finite."""


class NonRigidTransformError(InvalidInputError):
    """A 4×4 transform is not a proper rigid motion (rotation + translation)."""


class NoPlaneError(InfeasibleError):
    """No planar surface was found in a point cloud (seed Eq. 3.2: P_cl = ∅)."""


class MotionPlanningError(InfeasibleError):
    """No collision-free joint path was found within the attempts allowed."""


class StreamLengthError(InvalidInputError):
    """A blasting stream length outside the nozzle's safe window (seed §3.2.1)."""


class InternalError(PlannerError, RuntimeError):
    """A planner's own consistency check failed: a bug to report, not a fault of the input."""

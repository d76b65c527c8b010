"""Types of the plan-kind registry.

A plan kind couples a pydantic params model, a function that runs a pure
planner, the checks it computes, sample clouds and a compiler to robot
commands.  Adding a kind is one new module assigning ``KIND`` (found by
:mod:`server.kinds.catalog`; DESIGN §5, §6); its scene drawer is a module
of :mod:`server.scene` declaring ``DRAWS`` (found by kind name; kinds never
import the scene, the scene never imports the kinds).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any, Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, GetCoreSchemaHandler, ValidationError
from pydantic_core import CoreSchema, core_schema

import planners.result as planners_result
from server.planview import PlanView

__all__ = [
    "ID_MAX",
    "SEED_MAX",
    "SPAN_M",
    "WORLD_M",
    "Check",
    "CloudRef",
    "Coordinate",
    "JobContext",
    "KindOutput",
    "Offset",
    "PlanKind",
    "PlanView",
    "Seed",
    "StrictParams",
    "VertexId",
    "check_ge",
    "check_le",
    "drop_unknown_keys",
]

# Bounds of params numbers.  Every number of every kind's params has a lower
# and an upper bound in its schema: generous for real structures, small
# enough that a typo (``1e308``) is refused at submission instead of planned.

#: A coordinate in a cloud's (or the world) frame, metres: stored clouds keep
#: their survey frame, whose UTM or national-grid northings reach 10 000 km.
WORLD_M = 1.0e7
#: A length, or a position relative to a structure, on one structure (metres):
#: a bridge is under 2 km.
SPAN_M = 2000.0
#: Largest seed: numpy's legacy generator and the RANSAC seeds are 32-bit.
SEED_MAX = 2**32 - 1
#: Largest vertex or member id of a structure's graph (ids are numbered from
#: 0; a bridge model has thousands at most).
ID_MAX = 10**6

Coordinate = Annotated[float, Field(ge=-WORLD_M, le=WORLD_M)]
Offset = Annotated[float, Field(ge=-SPAN_M, le=SPAN_M)]
Seed = Annotated[int, Field(ge=0, le=SEED_MAX)]
VertexId = Annotated[int, Field(ge=0, le=ID_MAX)]


def _refuse_bool(value: Any) -> Any:
    """``value``, unless it is a boolean (``bool`` is an ``int`` to Python)."""
    if isinstance(value, bool):
        raise ValueError("a boolean is not a number")
    return value


def _strict_numbers(node: Any) -> None:
    """Make every int and float of a core schema strict, in place.

    Lax mode reads ``true`` as 1, ``"7"`` as 7 and ``2.0`` as the int 2;
    strict floats still take ints.  An int ``Literal`` (strict or not) takes
    ``true`` for 1, so it is wrapped in a check refusing booleans.
    """
    if isinstance(node, list):
        for item in node:
            _strict_numbers(item)
        return
    if not isinstance(node, dict):
        return
    kind = node.get("type")
    if kind in ("int", "float"):
        node["strict"] = True
    elif kind == "function-before" and node.get("function", {}).get("function") is _refuse_bool:
        return  # wrapped already (a nested model's schema is shared with its parent's)
    elif kind == "literal":
        expected = node.get("expected", [])
        if any(
            isinstance(v, int | float) and not isinstance(v, bool) for v in expected
        ) and not any(isinstance(v, bool) for v in expected):
            inner = dict(node)
            node.clear()
            node.update(core_schema.no_info_before_validator_function(_refuse_bool, inner))
        return
    for key, value in node.items():
        # defaults and metadata hold values, not schemas
        if key not in ("default", "metadata", "serialization", "expected"):
            _strict_numbers(value)


class StrictParams(BaseModel):
    """Base of every kind's params model (and its nested parts): unknown keys
    are refused with a 422 naming them, so a misspelt key (``strat`` for
    ``start``) cannot silently plan the defaults; NaN and infinities are
    refused (JSON as Python reads it allows them), and numbers are strict: a
    boolean or a numeric string is not a number, an int field takes no
    float."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    @classmethod
    def __get_pydantic_core_schema__(
        cls, source: type[BaseModel], handler: GetCoreSchemaHandler
    ) -> CoreSchema:
        schema = handler(source)
        _strict_numbers(schema)
        return schema


def drop_unknown_keys(
    model: type[BaseModel], params: dict[str, Any], only: Callable[[str], bool] | None = None
) -> tuple[dict[str, Any], list[str]]:
    """``params`` without the keys ``model`` forbids, and their dotted names.

    For params *stored* before models forbade unknown keys (old rows must still
    load and re-run) and for keys a revision inherits from its parent; ``only``
    limits the dropping to top-level keys it accepts, so keys a caller typed
    now are still refused.  Other validation errors are left for the caller's
    own ``model_validate`` to report.
    """
    try:
        model.model_validate(params)
        return params, []
    except ValidationError as exc:
        locs = [
            e["loc"]
            for e in exc.errors()
            if e["type"] == "extra_forbidden"
            and e["loc"]
            and (only is None or (isinstance(e["loc"][0], str) and only(e["loc"][0])))
        ]
    if not locs:
        return params, []
    cleaned = copy.deepcopy(params)
    for loc in locs:
        node: Any = cleaned
        for part in loc[:-1]:
            node = node[part]
        node.pop(loc[-1], None)
    return cleaned, [".".join(str(p) for p in loc) for loc in locs]


class Check(BaseModel):
    """One safety or quality check of a plan (DESIGN §4)."""

    name: str
    passed: bool
    value: float | str | bool | None = None
    limit: float | str | bool | None = None
    message: str = ""


def _stored(c: planners_result.Check) -> Check:
    return Check(name=c.name, passed=c.passed, value=c.value, limit=c.limit, message=c.message)


def check_le(name: str, value: float, limit: float, what: str, unit: str = "") -> Check:
    """``value <= limit`` as a :class:`Check` with a readable message
    (:func:`planners.result.check_le`)."""
    return _stored(planners_result.check_le(name, value, limit, what, unit))


def check_ge(name: str, value: float, limit: float, what: str, unit: str = "") -> Check:
    """``value >= limit`` as a :class:`Check` with a readable message
    (:func:`planners.result.check_ge`)."""
    return _stored(planners_result.check_ge(name, value, limit, what, unit))


@dataclass
class KindOutput:
    """What a kind's ``run`` returns; stored with the plan.

    ``result`` must be JSON-serialisable (numbers, strings, lists, dicts) and
    small; big arrays go in ``arrays`` and are written as ``.npy`` files.
    ``metrics`` is flat, with units in the names (``route_length_m``).
    """

    result: dict[str, Any] = field(default_factory=dict)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    checks: list[Check] = field(default_factory=list)
    metrics: dict[str, float] = field(default_factory=dict)

    @classmethod
    def from_result(cls, r: planners_result.PlanResult) -> KindOutput:
        """The stored form of a planner's :class:`planners.result.PlanResult`,
        passed through unchanged (the one result contract)."""
        return cls(
            result=r.summary,
            arrays=r.arrays,
            checks=[_stored(c) for c in r.checks],
            metrics={k: float(v) for k, v in r.metrics.items()},
        )


class JobContext(Protocol):
    """What a running planning job may use besides its params."""

    def progress(self, fraction: float, stage: str) -> None:
        """Report progress 0–1 and a stage name; raises
        :class:`planners.errors.CancelledError` once the plan was cancelled."""

    def load_cloud(self, cloud_id: str) -> np.ndarray:
        """An (N,3) float64 array of a stored cloud; ``KeyError``-free: raises
        :class:`planners.errors.InvalidInputError` for an unknown id."""


SampleFn = Callable[[int], np.ndarray]


@dataclass(frozen=True)
class PlanKind:
    """One registered plan kind."""

    name: str
    title: str
    params_model: type[BaseModel]
    run: Callable[[Any, JobContext], KindOutput]
    description: str = ""
    robot: str | None = None
    samples: Mapping[str, SampleFn] = field(default_factory=dict)
    #: Result → command program dicts; returning None means "nothing for the
    #: robot to do" (no program, not dispatchable).
    compile: Callable[[PlanView], list[dict[str, Any]] | None] | None = None
    #: Cheap semantic checks run synchronously at submission; raise a
    #: ``planners.errors.PlannerError`` to refuse the request with HTTP 422.
    validate: Callable[[Any], None] | None = None


class CloudRef(StrictParams):
    """Convenience params fragment: a stored cloud id or a sample name."""

    cloud_id: str | None = Field(None, description="id of a stored cloud (POST /clouds)")
    sample: str | None = Field(None, description="name of a sample scene when no cloud_id is given")

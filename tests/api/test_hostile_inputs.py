"""Hostile inputs get a clear 4xx naming what is wrong, never a 500 or a
silent acceptance: non-finite numbers, numbers beyond any structure,
booleans for numbers, clouds too small to plan on, unreadable E57 files."""

from __future__ import annotations

import json
import logging
import math
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from server.cloud_io import MIN_CLOUD_POINTS, CloudFormatError, read_cloud
from server.kinds import registry
from server.kinds.base import SEED_MAX

KINDS = sorted(registry())


def _post_raw(api: Any, path: str, body: str) -> Any:
    """POST ``body`` as it is: Python's json writes NaN / Infinity literals,
    which ``json=`` (strict JSON) would refuse to send."""
    headers = {**api.headers(), "Content-Type": "application/json"}
    return api.client.post(path, content=body.encode(), headers=headers)


def _plan(api: Any, kind: str, params: dict[str, Any]) -> Any:
    return _post_raw(api, "/api/v1/plans", json.dumps({"kind": kind, "params": params}))


def _errors(r: Any) -> list[dict[str, Any]]:
    detail = r.json()["detail"]
    assert isinstance(detail, list), detail
    return detail


# ----------------------------------------------------------------- schemas
_BOUND_KEYS = ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum")


def _unbounded(
    schema: dict[str, Any], defs: dict[str, Any], path: str, outer: dict[str, Any]
) -> list[str]:
    """Paths of number/integer schemas without a lower or an upper bound.

    Bounds beside an ``anyOf`` hold for its number branch (JSON Schema
    semantics); an ``enum`` or ``const`` is bounded by its members."""
    if "$ref" in schema:
        return _unbounded(defs[schema["$ref"].split("/")[-1]], defs, path, {})
    bounds = {**outer, **{k: schema[k] for k in _BOUND_KEYS if k in schema}}
    out: list[str] = []
    for branch in schema.get("anyOf", []) + schema.get("oneOf", []) + schema.get("allOf", []):
        out += _unbounded(branch, defs, path, bounds)
    if schema.get("type") in ("number", "integer") and not ({"enum", "const"} & set(schema)):
        low = "minimum" in bounds or "exclusiveMinimum" in bounds
        high = "maximum" in bounds or "exclusiveMaximum" in bounds
        if not (low and high):
            out.append(path)
    for name, sub in schema.get("properties", {}).items():
        out += _unbounded(sub, defs, f"{path}.{name}", {})
    if isinstance(schema.get("items"), dict):
        out += _unbounded(schema["items"], defs, f"{path}[]", {})
    for i, sub in enumerate(schema.get("prefixItems", [])):
        out += _unbounded(sub, defs, f"{path}[{i}]", {})
    if isinstance(schema.get("additionalProperties"), dict):
        out += _unbounded(schema["additionalProperties"], defs, f"{path}{{}}", {})
    return out


def test_every_number_of_every_kind_has_both_bounds(api) -> None:
    kinds = api.get("/api/v1/kinds", "viewer").json()
    assert sorted(k["name"] for k in kinds) == KINDS
    missing: list[str] = []
    for k in kinds:
        schema = k["params_schema"]
        missing += _unbounded(schema, schema.get("$defs", {}), k["name"], {})
    assert missing == []


@pytest.mark.parametrize("kind", KINDS)
def test_every_kinds_defaults_are_valid_params(kind: str) -> None:
    """pydantic does not validate defaults: a bound below a default would
    only show when the default is sent back."""
    model = registry()[kind].params_model
    defaults = model().model_dump(mode="json")
    assert model.model_validate(defaults) == model()


def _top_level_numbers(kind: str) -> list[tuple[str, str]]:
    """(field, "number" | "integer") of a kind's top-level numeric fields."""
    schema = registry()[kind].params_model.model_json_schema()
    out = []
    for name, prop in schema["properties"].items():
        for branch in [prop, *prop.get("anyOf", [])]:
            if branch.get("type") in ("number", "integer"):
                out.append((name, branch["type"]))
                break
    return out


NUMERIC_FIELDS = [(kind, name, t) for kind in KINDS for name, t in _top_level_numbers(kind)]


@pytest.mark.parametrize(("kind", "field", "kind_of_number"), NUMERIC_FIELDS)
def test_models_refuse_non_finite_and_boolean_numbers(
    kind: str, field: str, kind_of_number: str
) -> None:
    """The params models themselves, whoever calls them: NaN, infinities and
    booleans are not numbers, nor are numeric strings."""
    model = registry()[kind].params_model
    bad: list[Any] = [True, False, "1"]
    if kind_of_number == "number":
        bad += [math.nan, math.inf, -math.inf]
    else:
        bad += [1.5, 1e26]
    for value in bad:
        with pytest.raises(ValidationError) as exc:
            model.model_validate({field: value})
        assert [e["loc"] for e in exc.value.errors()] == [(field,)], (value, exc.value)


# ----------------------------------------------------------------- NaN / Infinity
def test_nan_and_infinity_in_params_are_422_naming_the_field(api) -> None:
    r = _plan(api, "demo.route", {"max_length_m": math.nan})
    assert r.status_code == 422, r.text
    assert _errors(r) == [
        {
            "type": "finite_number",
            "loc": ["max_length_m"],
            "msg": "Input should be a finite number",
            "input": "NaN",
        }
    ]
    r = _plan(api, "demo.route", {"nodes": {"a0": [0.0, 0.0, math.inf]}})
    assert r.status_code == 422 and _errors(r)[0]["loc"] == ["nodes", "a0", 2]
    polygon = {
        "origin_m": [0, 0, 0],
        "normal": [0, 0, 1],
        "boundary_m": [[0, 0], [1, -math.inf], [1, 1]],
    }
    r = _plan(api, "blast", {"polygon": polygon})
    assert r.status_code == 422 and _errors(r)[0]["loc"] == ["polygon", "boundary_m", 1, 1]
    assert api.get("/api/v1/plans").json() == []  # nothing was queued


def test_nan_outside_params_is_422_not_500(api) -> None:
    r = _post_raw(api, "/api/v1/plans", '{"kind": NaN, "params": {}}')
    assert r.status_code == 422 and _errors(r)[0]["loc"] == ["body", "kind"]
    r = _post_raw(api, "/api/v1/scene/frame", '{"point_m": [0, 0, NaN]}')
    assert r.status_code == 422 and _errors(r)[0]["loc"] == ["body", "point_m", 2]


def test_a_revision_with_nan_is_422(api) -> None:
    pid = api.submit("demo.route")["id"]
    r = _post_raw(api, f"/api/v1/plans/{pid}/revise", '{"params": {"step_delay_s": Infinity}}')
    assert r.status_code == 422 and _errors(r)[0]["loc"] == ["step_delay_s"]


_KEY = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=8)


@st.composite
def _params_with_one_non_finite(draw: st.DrawFn) -> tuple[str, dict[str, Any], list[Any]]:
    """(kind, params, loc): a NaN or infinity at ``loc``, inside dicts and
    lists, under one of the kind's own fields or an invented one."""
    kind = draw(st.sampled_from(KINDS))
    fields = list(registry()[kind].params_model.model_fields)
    first = draw(st.one_of(st.sampled_from(fields), _KEY))
    rest = draw(st.lists(st.one_of(_KEY, st.integers(0, 3)), max_size=4))
    value: Any = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
    for part in reversed(rest):
        value = {part: value} if isinstance(part, str) else [0.5] * part + [value]
    return kind, {first: value}, [first, *rest]


@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=_params_with_one_non_finite())
def test_any_non_finite_value_at_any_params_path_is_422(api, case) -> None:
    kind, params, loc = case
    r = _plan(api, kind, params)
    assert r.status_code == 422, r.text
    assert {"type": "finite_number", "loc": loc} in [
        {"type": e["type"], "loc": e["loc"]} for e in _errors(r)
    ]


# ----------------------------------------------------------------- bounds
def test_numbers_beyond_any_structure_are_refused(api) -> None:
    r = _plan(api, "demo.route", {"max_length_m": 1e308})
    assert r.status_code == 422 and _errors(r)[0]["loc"] == ["max_length_m"]
    for seed in (10**26, 2**32, -1):
        r = _plan(api, "ara.navigate", {"sample_seed": seed})
        assert r.status_code == 422 and _errors(r)[0]["loc"] == ["sample_seed"], seed
    r = _plan(api, "ara.navigate", {"sample_seed": 1e26})
    assert r.status_code == 422
    r = _plan(api, "sbg.inspect", {"girder": {"length_m": 1e6}})
    assert r.status_code == 422 and _errors(r)[0]["loc"] == ["girder", "length_m"]
    r = _plan(api, "demo.route", {"nodes": {"a0": [0, 0, 1e300]}})
    assert r.status_code == 422 and _errors(r)[0]["loc"] == ["nodes", "a0", 2]
    assert api.get("/api/v1/plans").json() == []


def test_the_largest_seed_and_survey_coordinates_are_accepted(api) -> None:
    registry()["ara.navigate"].params_model.model_validate({"seed": SEED_MAX})
    # a node in a UTM frame (northing 5.4e6 m) is a real coordinate
    nodes = {"a": [512_300.0, 5_401_200.0, 30.0], "b": [512_301.0, 5_401_200.0, 30.0]}
    api.submit("demo.route", {"nodes": nodes, "edges": [["a", "b"]], "start": "a", "end": "b"})


# ----------------------------------------------------------------- booleans
def test_booleans_are_not_numbers_in_plan_params(api) -> None:
    cases: list[tuple[str, dict[str, Any], list[Any]]] = [
        ("demo.route", {"max_length_m": True}, ["max_length_m"]),
        ("demo.route", {"nodes": {"a0": [0, 0, False]}}, ["nodes", "a0", 2]),
        ("ara.navigate", {"sample_seed": True}, ["sample_seed"]),
        ("sbg.inspect", {"direction": True}, ["direction"]),
        ("sbg.inspect", {"noise": {"range_sigma_mm": True}}, ["noise", "range_sigma_mm"]),
        ("cmbot.climb", {"guardrail": {"posts_m": [1.0, True]}}, ["guardrail", "posts_m", 1]),
    ]
    for kind, params, loc in cases:
        r = _plan(api, kind, params)
        assert r.status_code == 422, (kind, params, r.text)
        assert _errors(r)[0]["loc"] == loc, (kind, params, r.text)
    assert api.get("/api/v1/plans").json() == []
    # ints are numbers: 12 for a float field plans
    assert _plan(api, "demo.route", {"max_length_m": 12}).status_code == 202


def test_booleans_are_not_coordinates_of_the_scene_frame(api) -> None:
    r = _post_raw(api, "/api/v1/scene/frame", '{"point_m": [0, 0, false]}')
    assert r.status_code == 422 and _errors(r)[0]["loc"] == ["body", "point_m", 2]
    # ints and floats pass validation (then 503: this app runs no scene)
    for point in ("[0, 0, 1.5]", "[0, 1, 2]"):
        r = _post_raw(api, "/api/v1/scene/frame", f'{{"point_m": {point}}}')
        assert r.status_code == 503, r.text


# ----------------------------------------------------------------- clouds
def _xyz(n: int) -> bytes:
    return b"".join(f"{i * 0.1:.1f} {i % 3} 0.5\n".encode() for i in range(n))


def test_a_cloud_too_small_for_any_kind_is_422_naming_the_minimum(api) -> None:
    for n in (1, MIN_CLOUD_POINTS - 1):
        r = api.post("/api/v1/clouds", files={"file": ("tiny.xyz", _xyz(n))})
        assert r.status_code == 422, r.text
        detail = r.json()["detail"]
        assert "tiny.xyz" in detail and f"at least {MIN_CLOUD_POINTS} points" in detail
    # non-finite rows do not count
    r = api.post("/api/v1/clouds", files={"file": ("nan.xyz", _xyz(5) + b"nan 0 0\n" * 20)})
    assert r.status_code == 422 and "5 point(s)" in r.json()["detail"]
    assert api.get("/api/v1/clouds").json() == []
    files = api.services.store.data_dir.rglob("*.npy")
    assert [p.name for p in files if "clouds" in p.parts] == []  # nothing half-stored
    r = api.post("/api/v1/clouds", files={"file": ("enough.xyz", _xyz(MIN_CLOUD_POINTS))})
    assert r.status_code == 201 and r.json()["n_points"] == MIN_CLOUD_POINTS


# ----------------------------------------------------------------- E57
CORRUPT_E57 = b"ASTM-E57" + b"\0" * 2040  # the signature, then a page whose checksum is wrong


def test_an_unreadable_e57_is_a_message_for_people() -> None:
    with pytest.raises(CloudFormatError) as exc:
        read_cloud(CORRUPT_E57, "bridge.e57")
    message = str(exc.value)
    assert message.startswith("not a readable E57 file: "), message
    assert "checksum" in message and "\n" not in message
    for leak in ("/", "tmp", ".cpp", "Debug info", "libE57", "Error"):
        assert leak not in message.removeprefix("not a readable E57 file: "), message


def test_an_unreadable_e57_upload_is_400_and_logged_in_full(api, caplog) -> None:
    caplog.set_level(logging.WARNING, logger="server.routers.clouds")
    r = api.post("/api/v1/clouds", files={"file": ("bridge.e57", CORRUPT_E57)})
    assert r.status_code == 400, r.text
    detail = r.json()["detail"]
    assert detail.startswith("bridge.e57: not a readable E57 file: "), detail
    for leak in ("/tmp", ".tmp-e57", ".cpp", "Debug info", "libE57"):
        assert leak not in detail, detail
    logged = "\n".join(rec.getMessage() for rec in caplog.records)
    assert "Debug info" in logged and ".tmp-e57" in logged  # the full report, server-side


@pytest.mark.parametrize(
    "path, body",
    [
        ("/api/v1/estop", '{"reason": NaN}'),
        ("/api/v1/webhooks", '{"url": Infinity, "events": ["plan"]}'),
        ("/api/v1/tokens", '{"name": -Infinity, "role": "viewer"}'),
    ],
)
def test_a_non_finite_number_in_any_body_is_a_422(api: Any, path: str, body: str) -> None:
    """Not only plans and the scene: every route's 422 can be sent (strict JSON)."""
    headers = {**api.headers("admin"), "Content-Type": "application/json"}
    r = api.client.post(path, content=body.encode(), headers=headers)
    assert r.status_code == 422, r.text
    assert any(str(e.get("input")) in ("NaN", "Infinity", "-Infinity") for e in r.json()["detail"])

"""Documented error responses shared by the routers (OpenAPI ``responses=``).

Every error the API sends is ``{"detail": ...}``: a message string, a list of
pydantic validation errors, or (409 of approve) an object with the reasons;
a few add fields beside ``detail`` (409 of an illegal transition carries
``state`` and ``allowed_actions``).  :func:`errors` documents the codes a
route can answer with that one model, so a client (or a fuzzer checking
status-code and schema conformance) knows every response it can get.  A
route that lists 422 here replaces FastAPI's default 422 schema, whose
``detail`` is a list only.
"""

from __future__ import annotations

import json
import re
from typing import Any

from fastapi import FastAPI, Response
from fastapi.encoders import jsonable_encoder
from pydantic import BaseModel, ConfigDict, Field

DESCRIPTIONS: dict[int, str] = {
    400: "the request body is malformed (e.g. an unreadable point-cloud file)",
    401: "missing, invalid, expired or revoked token",
    403: "the token's role may not do this",
    404: "no such resource",
    409: "the resource is in a state that does not allow this",
    413: "the request body exceeds the upload limit (STEELPATH_MAX_UPLOAD_MB)",
    415: "unsupported content type",
    422: "the request is well formed but its values are invalid",
    503: "the service this needs is not running",
}


def json_text(obj: Any) -> str:
    """Strict, compact JSON of plain data (what the store's records give).

    ``json.dumps`` in C, with FastAPI's ``jsonable_encoder`` only for a value
    JSON has no type for: walking every answer through ``jsonable_encoder``
    in Python was the largest share of a busy server's time on ``GET
    /plans/{id}``.
    """
    return json.dumps(obj, allow_nan=False, separators=(",", ":"), default=jsonable_encoder)


def json_response(obj: Any, status_code: int = 200) -> Response:
    """``obj`` as an ``application/json`` response, encoded by :func:`json_text`."""
    return Response(json_text(obj).encode("utf-8"), status_code, media_type="application/json")


class ErrorBody(BaseModel):
    """Every error response: ``detail`` says what was wrong."""

    model_config = ConfigDict(extra="allow")

    detail: str | list[dict[str, Any]] | dict[str, Any] = Field(
        ..., description="a message, a list of validation errors, or an object of reasons"
    )


def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """``responses=`` entries for ``codes``, each with :class:`ErrorBody`."""
    unknown = [c for c in codes if c not in DESCRIPTIONS]
    if unknown:
        raise ValueError(f"no description for status codes {unknown}")
    return {c: {"model": ErrorBody, "description": DESCRIPTIONS[c]} for c in codes}


#: What any route behind a token can answer besides its own codes.
AUTH = errors(401, 403, 422)


#: The shared set for a route that documents none of its own errors.
SHARED = (400, 401, 403, 404, 409, 422, 503)
#: What any route can answer: a body FastAPI cannot parse (400), token checks,
#: request validation.
ALWAYS = (400, 401, 403, 422)
REF = "#/components/schemas/ErrorBody"


def document_errors(app: FastAPI) -> None:
    """Make the app's OpenAPI document every error status each route can answer.

    An operation that declares :class:`ErrorBody` responses of its own keeps
    them (plus :data:`ALWAYS`); one that declares none gets :data:`SHARED`.  Every error
    response uses :class:`ErrorBody`: FastAPI's default 422 says ``detail`` is
    always a list, but semantic checks answer with a message.  Applied to the
    finished schema when it is first built, so every router counts.
    """
    build = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is not None:
            return app.openapi_schema
        schema = build()
        comps = schema.setdefault("components", {}).setdefault("schemas", {})
        comps.setdefault("ErrorBody", ErrorBody.model_json_schema())
        for ops in schema.get("paths", {}).values():
            for op in ops.values():
                if not isinstance(op, dict) or "responses" not in op:
                    continue
                responses = op["responses"]
                own = {c for c, r in responses.items() if REF in json.dumps(r)}
                codes = {int(c) for c in own} | (set(ALWAYS) if own else set(SHARED))
                for code in sorted(codes):
                    entry = responses.setdefault(str(code), {})
                    entry.setdefault("description", DESCRIPTIONS[code])
                    entry["content"] = {"application/json": {"schema": {"$ref": REF}}}
        return schema

    app.openapi = openapi  # type: ignore[method-assign]


class AllowFromSchema:
    """ASGI middleware: a 405's ``Allow`` lists every method the path has.

    Starlette answers 405 from the first route whose path matched, so a path
    served by several routes (``GET`` and ``DELETE /plans/{id}``) advertised
    only one method.  The methods come from the app's OpenAPI paths.
    """

    def __init__(self, app: Any, fastapi_app: FastAPI) -> None:
        self.app = app
        self.fastapi_app = fastapi_app
        self._paths: list[tuple[re.Pattern[str], str]] | None = None

    def _allowed(self, path: str) -> str | None:
        if self._paths is None:
            self._paths = []
            for template, ops in self.fastapi_app.openapi().get("paths", {}).items():
                rx = re.sub(r"\\\{[^/]+?\\\}", "[^/]+", re.escape(template))
                methods = ", ".join(sorted(m.upper() for m in ops if m != "parameters"))
                self._paths.append((re.compile(f"^{rx}$"), methods))
        return next((m for rx, m in self._paths if rx.match(path)), None)

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def patched(message: dict[str, Any]) -> None:
            if message["type"] == "http.response.start" and message["status"] == 405:
                allowed = self._allowed(scope["path"])
                if allowed:
                    headers = [
                        (k, v) for k, v in message.get("headers", []) if k.lower() != b"allow"
                    ]
                    message = {**message, "headers": [*headers, (b"allow", allowed.encode())]}
            await send(message)

        await self.app(scope, receive, patched)


def conform_openapi(app: FastAPI) -> None:
    """Document every route's errors (:func:`document_errors`) and make 405
    responses list the path's methods (:class:`AllowFromSchema`)."""
    document_errors(app)
    app.add_middleware(AllowFromSchema, fastapi_app=app)

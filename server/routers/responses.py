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

from typing import Any

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

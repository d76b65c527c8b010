"""``/api/v1/tokens`` (admin) and ``/api/v1/session`` (the console's cookie login).

Revoking a token also ends the event streams and scene websockets opened with
it (they watch it through :func:`server.auth.until_invalid`), within about
0.25 s in this process.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Request, Response
from pydantic import BaseModel, Field

from server.auth import (
    COOKIE,
    CSRF_COOKIE,
    MAX_LIFETIME_S,
    Admin,
    TokenRefused,
    Viewer,
    create_token,
    resolve,
    set_csrf_cookie,
)
from server.services import Services, get_services

router = APIRouter(tags=["auth"])

Svc = Annotated[Services, Depends(get_services)]


class TokenRequest(BaseModel):
    name: str = Field(..., min_length=1, max_length=100, description="who or what holds it")
    role: Literal["viewer", "operator", "admin"] = "operator"
    expires_in_s: int | None = Field(
        None,
        ge=1,
        le=MAX_LIFETIME_S,
        description="lifetime in seconds from now (e.g. 2592000 for 30 days); "
        "omitted or null: the token never expires",
    )


@router.get("/tokens")
def list_tokens(services: Svc, _: Admin) -> list[dict[str, Any]]:
    return [t.public() for t in services.store.list_tokens()]


@router.post("/tokens", status_code=201)
def new_token(req: TokenRequest, services: Svc, who: Admin) -> dict[str, Any]:
    """Create a token; the secret is in this response only."""
    tid, secret = create_token(
        services.store, req.name, req.role, who.actor, expires_in_s=req.expires_in_s
    )
    return {**services.store.get_token(tid).public(), "token": secret}


@router.delete("/tokens/{token_id}")
def revoke_token(token_id: str, services: Svc, who: Admin) -> dict[str, Any]:
    if token_id == who.token_id:
        raise HTTPException(409, detail="refusing to revoke the token making this request")
    return services.store.revoke_token(token_id, who.actor).public()


class SessionRequest(BaseModel):
    token: str = Field(..., min_length=8)


@router.post("/session")
def login(
    req: SessionRequest, request: Request, services: Svc, response: Response
) -> dict[str, Any]:
    """Exchange a token for an HttpOnly session cookie (console, scene, events).

    A fresh ``steelpath_csrf`` cookie comes with it: the console echoes it in
    ``X-CSRF-Token`` on every write (``server.auth.CsrfGuard``)."""
    try:
        principal = resolve(services.store, req.token)
    except TokenRefused as exc:
        raise HTTPException(401, detail=exc.detail) from None
    response.set_cookie(
        COOKIE,
        req.token,
        httponly=True,
        samesite="strict",
        secure=request.url.scheme == "https",
        path="/",
    )
    set_csrf_cookie(response, secure=request.url.scheme == "https")
    return {"name": principal.name, "role": principal.role}


@router.get("/session")
def whoami(who: Viewer) -> dict[str, Any]:
    return {"name": who.name, "role": who.role, "token_id": who.token_id}


@router.delete("/session", status_code=204)
def logout(response: Response) -> Response:
    response.delete_cookie(COOKIE, path="/")
    response.delete_cookie(CSRF_COOKIE, path="/")
    response.status_code = 204
    return response

"""Bearer-token authentication with roles viewer < operator < admin (DESIGN §6).

Tokens are 256-bit random strings; only their SHA-256 is stored (a fast hash
is enough for random secrets of this size — there is nothing to brute-force).
The console's browser session carries the same token in an HttpOnly cookie so
that the scene iframe and the event stream, which cannot set headers, are
authenticated too.
"""

from __future__ import annotations

import hashlib
import os
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from fastapi import Depends, HTTPException, Request, status

from server.services import Services, get_services
from server.store import Store

ROLES: dict[str, int] = {"viewer": 0, "operator": 1, "admin": 2}
COOKIE = "steelpath_token"
TOKEN_PREFIX = "sp_"


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def generate_token() -> str:
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def create_token(store: Store, name: str, role: str, actor: str) -> tuple[str, str]:
    """Create a token; returns ``(token_id, secret)``.  The secret is not stored."""
    if role not in ROLES:
        raise ValueError(f"unknown role {role!r}; choose one of {', '.join(ROLES)}")
    secret = generate_token()
    rec = store.add_token(name, role, hash_token(secret), actor)
    return rec.id, secret


def bootstrap_admin(store: Store, token_file: Path | None) -> str | None:
    """On first start (no active tokens) create an admin token and return it once."""
    if store.count_active_tokens() > 0:
        return None
    _, secret = create_token(store, "first-start admin", "admin", "system")
    if token_file is not None:
        token_file.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(token_file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as fh:
            fh.write(secret + "\n")
    return secret


@dataclass(frozen=True)
class Principal:
    token_id: str
    name: str
    role: str

    @property
    def actor(self) -> str:
        return f"{self.name} ({self.token_id})"

    def has(self, role: str) -> bool:
        return ROLES[self.role] >= ROLES[role]


def token_from_request(request: Request) -> str | None:
    header = request.headers.get("authorization", "")
    scheme, _, value = header.partition(" ")
    if scheme.lower() == "bearer" and value.strip():
        return value.strip()
    return request.cookies.get(COOKIE)


def authenticate(services: Services, token: str | None) -> Principal | None:
    if not token:
        return None
    rec = services.store.find_token(hash_token(token))
    if rec is None:
        return None
    return Principal(rec.id, rec.name, rec.role)


def require(role: str):
    """Dependency: a principal with at least ``role`` or 401/403."""

    def dependency(
        request: Request, services: Annotated[Services, Depends(get_services)]
    ) -> Principal:
        token = token_from_request(request)
        principal = authenticate(services, token)
        if principal is None:
            raise HTTPException(
                status.HTTP_401_UNAUTHORIZED,
                detail="missing or invalid token: send 'Authorization: Bearer <token>' "
                "(create one with 'steelpath token create --role operator')"
                if token is None
                else "invalid or revoked token",
                headers={"WWW-Authenticate": "Bearer"},
            )
        if not principal.has(role):
            raise HTTPException(
                status.HTTP_403_FORBIDDEN,
                detail=f"this action needs the {role} role; token {principal.name!r} has "
                f"{principal.role}",
            )
        return principal

    return dependency


Viewer = Annotated[Principal, Depends(require("viewer"))]
Operator = Annotated[Principal, Depends(require("operator"))]
Admin = Annotated[Principal, Depends(require("admin"))]

"""Bearer-token authentication with roles viewer < operator < admin (DESIGN §6).

Tokens are 256-bit random strings; only their SHA-256 is stored (a fast hash
is enough for random secrets of this size — there is nothing to brute-force).
The console's browser session carries the same token in an HttpOnly cookie so
that the scene iframe and the event stream, which cannot set headers, are
authenticated too.

A token may carry an expiry.  Long-lived connections (event streams, scene
websockets) are checked for the whole of their life, not only at the
handshake: :func:`until_invalid` returns once the token is revoked or expired.
It compares the expiry with the clock and the store's in-process revocation
counter every ``poll_s`` (0.25 s), and re-reads the token row on a change of
that counter or every ``recheck_s`` (0.75 s, so a revocation made
by another process such as ``steelpath token revoke`` closes it within 1 s too).

The cookie is an ambient credential: a browser sends it with a request any
page makes, including a page on another port of the same host (which is
*same-site*, so ``SameSite=Strict`` lets it through).  :class:`CsrfGuard`
therefore refuses an unsafe request (POST, PUT, PATCH, DELETE) authenticated
by the cookie unless it comes from this server's own origin *and* carries the
double-submit token: the ``steelpath_csrf`` cookie's value (random, readable
by the console's script) in an ``X-CSRF-Token`` header.  A request with an
``Authorization: Bearer`` header carries no ambient credential and is not
checked, so API clients (and their E-stop) are unaffected.
"""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import logging
import os
import re
import secrets
import threading
import time
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Annotated
from urllib.parse import urlsplit

import anyio
from fastapi import Depends, HTTPException, Request, Response, status
from starlette.requests import cookie_parser
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from server.asgi_response import send_json
from server.services import Services, get_services
from server.store import Store

log = logging.getLogger(__name__)

ROLES: dict[str, int] = {"viewer": 0, "operator": 1, "admin": 2}
COOKIE = "steelpath_token"
TOKEN_PREFIX = "sp_"
#: The double-submit CSRF cookie (not HttpOnly: the console's script reads it).
CSRF_COOKIE = "steelpath_csrf"
CSRF_HEADER = "X-CSRF-Token"


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def generate_token() -> str:
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


#: Longest accepted token lifetime (10 years): beyond that, use no expiry.
MAX_LIFETIME_S = 10 * 365 * 86400
_UNITS = {"s": 1, "m": 60, "h": 3600, "d": 86400}
_DURATION = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*([smhd])\s*$")


def parse_duration(text: str) -> float:
    """``"30d"``, ``"12h"``, ``"15m"``, ``"90s"`` → seconds; ``ValueError`` otherwise."""
    m = _DURATION.match(text or "")
    if m is None:
        raise ValueError(
            f"invalid duration {text!r}: give a number with a unit s, m, h or d (e.g. 30d, 12h)"
        )
    seconds = float(m.group(1)) * _UNITS[m.group(2)]
    check_lifetime(seconds)
    return seconds


def check_lifetime(seconds: float) -> None:
    if not (0 < seconds <= MAX_LIFETIME_S):
        raise ValueError(
            f"token lifetime must be more than 0 s and at most {MAX_LIFETIME_S} s "
            f"(10 years); got {seconds:g} s"
        )


def create_token(
    store: Store, name: str, role: str, actor: str, *, expires_in_s: float | None = None
) -> tuple[str, str]:
    """Create a token; returns ``(token_id, secret)``.  The secret is not stored.

    ``expires_in_s`` (seconds from now) makes it expire; ``None`` never expires.
    """
    if role not in ROLES:
        raise ValueError(f"unknown role {role!r}; choose one of {', '.join(ROLES)}")
    expires_at = None
    if expires_in_s is not None:
        check_lifetime(expires_in_s)
        expires_at = (datetime.now(UTC) + timedelta(seconds=expires_in_s)).isoformat(
            timespec="milliseconds"
        )
    secret = generate_token()
    rec = store.add_token(name, role, hash_token(secret), actor, expires_at=expires_at)
    return rec.id, secret


def bootstrap_admin(store: Store, token_file: Path | None) -> str | None:
    """On first start (no active tokens) create an admin token and return it once.

    The check and the insert are one transaction (``Store.add_first_token``):
    of several servers starting on one empty store, exactly one creates it."""
    if store.count_active_tokens() > 0:
        return None
    secret = generate_token()
    if store.add_first_token("first-start admin", "admin", hash_token(secret), "system") is None:
        return None  # another server sharing the store made it first
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
    expires_at: float | None = None  # Unix time; None: never

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


MISSING_TOKEN = (
    "missing or invalid token: send 'Authorization: Bearer <token>' "
    "(create one with 'steelpath token create --role operator')"
)
INVALID_TOKEN = "invalid or revoked token"


class TokenRefused(Exception):
    """The token cannot be used; ``detail`` says why (missing, unknown, revoked, expired)."""

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail


def resolve(store: Store, token: str | None) -> Principal:
    """The principal a token stands for, or :class:`TokenRefused` saying why not."""
    if not token:
        raise TokenRefused(MISSING_TOKEN)
    rec = store.lookup_token(hash_token(token))
    if rec is None:
        raise TokenRefused(INVALID_TOKEN)
    if rec.revoked_at is not None:
        raise TokenRefused(f"token revoked at {rec.revoked_at}; ask an admin for a new one")
    if rec.expired():
        raise TokenRefused(
            f"token expired at {rec.expires_at}; ask an admin for a new one "
            "('steelpath token create --expires-in 30d')"
        )
    return Principal(rec.id, rec.name, rec.role, rec.expires_ts)


class TokenCache:
    """Tokens resolved in the last ``ttl_s`` seconds, so a request needs no SQLite read.

    Every API request authenticates; under load a database read (and the
    worker-thread hop it needs) per request is what queued reads behind each
    other.  A hit costs a SHA-256 and a dict lookup.  Entries die after
    ``ttl_s`` (0.75 s, the same bound :class:`CredentialWatch` gives a
    revocation made by another process) and all at once when a revocation
    goes through this process's store; an expiry is checked on every hit.
    Refusals are not cached.  At most ``max_entries`` tokens are kept.
    """

    def __init__(self, store: Store, *, ttl_s: float = 0.75, max_entries: int = 4096) -> None:
        self.store = store
        self.ttl_s = ttl_s
        self.max_entries = max_entries
        self._entries: dict[str, tuple[Principal, float]] = {}
        self._epoch = store.token_epoch
        self._lock = threading.Lock()

    def hit(self, token: str) -> Principal | None:
        """The cached principal for ``token``, or ``None`` (then call :meth:`resolve`)."""
        key = hash_token(token)
        now = time.monotonic()
        with self._lock:
            if self.store.token_epoch != self._epoch:
                self._entries.clear()
                self._epoch = self.store.token_epoch
            entry = self._entries.get(key)
            if entry is None:
                return None
            principal, until = entry
            if now >= until or (
                principal.expires_at is not None and time.time() >= principal.expires_at
            ):
                del self._entries[key]
                return None
            return principal

    def resolve(self, token: str | None) -> Principal:
        """Read the token from the store (blocking) and remember it; TokenRefused if unusable."""
        epoch = self.store.token_epoch
        principal = resolve(self.store, token)
        assert token is not None  # resolve refuses a missing token
        with self._lock:
            if epoch == self._epoch:  # no revocation raced this read
                if len(self._entries) >= self.max_entries:
                    self._entries.clear()
                self._entries[hash_token(token)] = (principal, time.monotonic() + self.ttl_s)
        return principal


def token_cache(services: Services) -> TokenCache:
    """The app's :class:`TokenCache` (made on first use)."""
    cache = services.token_cache
    if cache is None:
        cache = services.token_cache = TokenCache(services.store)
    return cache


def authenticate(services: Services, token: str | None) -> Principal | None:
    """The principal for ``token`` or ``None``; blocking on a cache miss."""
    if not token:
        return None
    cache = token_cache(services)
    try:
        return cache.hit(token) or cache.resolve(token)
    except TokenRefused:
        return None


async def authenticate_async(services: Services, token: str | None) -> Principal:
    """The principal for ``token``, or TokenRefused; the store is read off the event loop."""
    if not token:
        raise TokenRefused(MISSING_TOKEN)
    cache = token_cache(services)
    principal = cache.hit(token)
    if principal is None:
        principal = await anyio.to_thread.run_sync(cache.resolve, token)
    return principal


class CredentialWatch:
    """Whether a principal's token is still good, cheap enough to ask often.

    ``check()`` costs a clock read and an integer compare unless the store's
    revocation counter moved or ``recheck_s`` passed; then it re-reads the row
    (a blocking SQLite read: call it off the event loop, as
    :func:`until_invalid` does).
    """

    def __init__(self, store: Store, principal: Principal, *, recheck_s: float = 0.75) -> None:
        self.store = store
        self.principal = principal
        self.recheck_s = recheck_s
        self._epoch = store.token_epoch
        self._next_read = time.monotonic() + recheck_s

    def needs_read(self) -> bool:
        return self.store.token_epoch != self._epoch or time.monotonic() >= self._next_read

    def expired(self) -> bool:
        exp = self.principal.expires_at
        return exp is not None and time.time() >= exp

    def read(self) -> str | None:
        """Re-read the token row; the reason it is no longer valid, or ``None``."""
        self._epoch = self.store.token_epoch
        self._next_read = time.monotonic() + self.recheck_s
        try:
            rec = self.store.get_token(self.principal.token_id)
        except KeyError:
            return "token deleted"
        if rec.revoked_at is not None:
            return "token revoked"
        if rec.expired():
            return "token expired"
        return None


async def until_invalid(
    store: Store, principal: Principal, *, poll_s: float = 0.25, recheck_s: float = 0.75
) -> str:
    """Return (``"token revoked"`` / ``"token expired"`` …) once the token stops being valid.

    Run it as a task beside a long-lived connection and close the connection
    when it returns; cancel it when the connection ends first.
    """
    watch = CredentialWatch(store, principal, recheck_s=recheck_s)
    while True:
        if watch.expired():
            return "token expired"
        if watch.needs_read():
            # SQLite may wait on a writer's lock: never on the event loop.
            reason = await asyncio.to_thread(watch.read)
            if reason is not None:
                return reason
        await asyncio.sleep(poll_s)


def require(role: str):
    """Dependency: a principal with at least ``role`` or 401/403."""

    # async, so that authenticating costs no worker-thread hop (a cache hit is
    # a dict lookup); a miss reads the store on a worker thread.
    async def dependency(
        request: Request, services: Annotated[Services, Depends(get_services)]
    ) -> Principal:
        token = token_from_request(request)
        try:
            principal = await authenticate_async(services, token)
        except TokenRefused as exc:
            raise HTTPException(
                status.HTTP_401_UNAUTHORIZED,
                detail=exc.detail,
                headers={"WWW-Authenticate": "Bearer"},
            ) from None
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


# ------------------------------------------------------------------------ CSRF
#: Methods that change state; a cookie-authenticated one must pass :class:`CsrfGuard`.
UNSAFE_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})
#: Signing in authenticates with the token in its body, not with the cookie
#: (which a browser may still hold from an expired session): not checked.
SIGN_IN = ("POST", "/api/v1/session")
_DEFAULT_PORTS = {"http": 80, "https": 443}
_OriginKey = tuple[str, str, int]


def new_csrf_token() -> str:
    return secrets.token_urlsafe(32)


def csrf_set_cookie(value: str, *, secure: bool) -> str:
    """A ``Set-Cookie`` header value for the CSRF cookie: SameSite=Strict, not HttpOnly."""
    return f"{CSRF_COOKIE}={value}; Path=/; SameSite=Strict" + ("; Secure" if secure else "")


def set_csrf_cookie(response: Response, *, secure: bool) -> None:
    """Give the browser a fresh CSRF cookie (at sign-in, beside the token cookie)."""
    response.set_cookie(
        CSRF_COOKIE, new_csrf_token(), httponly=False, samesite="strict", secure=secure, path="/"
    )


def _is_bearer(authorization: str) -> bool:
    """Whether :func:`token_from_request` takes the token from this header (not the cookie)."""
    scheme, _, value = authorization.partition(" ")
    return scheme.lower() == "bearer" and bool(value.strip())


def _origin_key(scheme: str, netloc: str) -> _OriginKey | None:
    """``(scheme, host, port)`` with the scheme's default port filled in, or ``None``."""
    if scheme not in _DEFAULT_PORTS or not netloc:
        return None
    try:
        parts = urlsplit(f"//{netloc}")
        host, port = parts.hostname, parts.port
    except ValueError:
        return None
    if not host:
        return None
    return scheme, host.lower(), port or _DEFAULT_PORTS[scheme]


def _own_origins(scope: Scope, headers: dict[str, str]) -> tuple[set[_OriginKey], str]:
    """This server's origin(s) as the browser sees it, and one of them as text.

    The host (and port) is the request's ``Host``.  The scheme is the
    connection's, or ``X-Forwarded-Proto``'s where a proxy ends TLS in front of
    the server: a page cannot set that header on a cross-origin request
    without a CORS preflight, which this server never grants.
    """
    host = headers.get("host", "")
    schemes = [str(scope.get("scheme", "http"))]
    forwarded = headers.get("x-forwarded-proto", "").split(",")[0].strip().lower()
    if forwarded in _DEFAULT_PORTS and forwarded not in schemes:
        schemes.append(forwarded)
    keys = {k for k in (_origin_key(s, host) for s in schemes) if k is not None}
    return keys, f"{schemes[-1]}://{host}"


def csrf_refusal(scope: Scope, headers: dict[str, str], cookies: dict[str, str]) -> str | None:
    """Why a cookie-authenticated write is refused, or ``None`` when it passes.

    ``headers`` are lower-case names; ``cookies`` the request's cookies.
    """
    origin = headers.get("origin")
    own, own_text = _own_origins(scope, headers)
    hint = "API clients: send 'Authorization: Bearer <token>' instead of the session cookie"
    if origin is not None and origin != "null":
        try:
            parts = urlsplit(origin)
            key = _origin_key(parts.scheme, parts.netloc)
        except ValueError:
            key = None
        if key is None or key not in own:
            return (
                f"CSRF origin check failed: Origin {origin!r} is not this server's origin "
                f"{own_text!r}; a write with the session cookie must come from the console ({hint})"
            )
    else:
        # A browser sends "Origin: null" on a same-origin POST from a page whose
        # Referrer-Policy is no-referrer (Fetch standard); Sec-Fetch-Site, which
        # no page can set, still says where the request came from.
        site = headers.get("sec-fetch-site")
        if site != "same-origin":
            why = "Origin is null" if origin == "null" else "no Origin header"
            return (
                f"CSRF origin check failed: {why} and Sec-Fetch-Site is {site!r}, "
                f"not 'same-origin' ({hint})"
            )
    expected = cookies.get(CSRF_COOKIE, "")
    sent = headers.get(CSRF_HEADER.lower(), "")
    if not expected or not sent or not hmac.compare_digest(sent.encode(), expected.encode()):
        if not expected:
            what = "the steelpath_csrf cookie is missing"
        elif not sent:
            what = f"the {CSRF_HEADER} header is missing"
        else:
            what = f"the {CSRF_HEADER} header does not match the steelpath_csrf cookie"
        return (
            f"CSRF token check failed: {what}; send the "
            "steelpath_csrf cookie's value in it (the console does: reload it), or send "
            "'Authorization: Bearer <token>' instead of the session cookie"
        )
    return None


class CsrfGuard:
    """ASGI middleware: cookie-authenticated writes need this origin and the CSRF token.

    Refused with 403 and a JSON ``detail`` naming the failed check.  Requests
    with a bearer token, every GET/HEAD/OPTIONS, and signing in (``POST
    /api/v1/session``, authenticated by the token in its body) pass untouched.
    A safe request for the console page, or one carrying the session cookie,
    that lacks the CSRF cookie gets one (``Set-Cookie``), so a console signed
    in before the cookie existed, or one whose cookie was cleared, has it
    again at its next read.  Pure ASGI, not ``BaseHTTPMiddleware``: the E-stop
    request passes through it and must not wait for a task hop.
    """

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers: dict[str, str] = {}
        for raw_name, raw_value in scope.get("headers") or []:
            name, value = raw_name.decode("latin-1").lower(), raw_value.decode("latin-1")
            if name == "cookie" and name in headers:  # HTTP/2 sends one header per cookie
                headers[name] += "; " + value
            else:
                headers.setdefault(name, value)
        cookies = cookie_parser(headers.get("cookie", ""))
        if scope["method"] in UNSAFE_METHODS:
            if (
                cookies.get(COOKIE)
                and not _is_bearer(headers.get("authorization", ""))
                and (scope["method"], scope["path"]) != SIGN_IN
            ):
                refusal = csrf_refusal(scope, headers, cookies)
                if refusal is not None:
                    log.warning(
                        "refused a cookie-authenticated %s %s (Origin %r): %s",
                        scope["method"],
                        scope["path"],
                        headers.get("origin"),
                        refusal.split(":")[0],
                    )
                    await send_json(send, 403, {"detail": refusal})
                    return
            await self.app(scope, receive, send)
            return
        if CSRF_COOKIE in cookies or (scope["path"] != "/" and COOKIE not in cookies):
            await self.app(scope, receive, send)
            return
        own, _ = _own_origins(scope, headers)
        secure = any(key[0] == "https" for key in own) or scope.get("scheme") == "https"
        cookie = csrf_set_cookie(new_csrf_token(), secure=secure).encode("latin-1")

        async def send_with_cookie(message: Message) -> None:
            if message["type"] == "http.response.start":
                message = {
                    **message,
                    "headers": [*message.get("headers", []), (b"set-cookie", cookie)],
                }
            await send(message)

        await self.app(scope, receive, send_with_cookie)

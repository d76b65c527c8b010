"""Security headers on every response: no MIME sniffing, no referrer, and a
Content-Security-Policy with framing limits on every page.

Every response gets ``X-Content-Type-Options: nosniff`` and
``Referrer-Policy: no-referrer``.  A document (HTML, or SVG, which can run
script too) also gets ``X-Frame-Options: SAMEORIGIN`` and a CSP; which one
depends on what the page needs:

- the console and any other page: ``'self'`` only.  The console has no inline
  script or style (``web_static/``; uPlot styles through the CSSOM, which a
  CSP does not restrict), loads its vendored libraries from ``/static/vendor``
  and embeds the scene from this origin;
- the 3D scene (``/scene/``, viser's page through the proxy): viser ships as
  one page whose inline loader inflates a WebAssembly decoder and then
  inserts the app as an inline module script and an inline stylesheet, so it
  needs ``'unsafe-inline'`` and ``'wasm-unsafe-eval'``; the app's Emscripten
  (embind) module builds its call wrappers with ``Function(...)``, which
  throws without ``'unsafe-eval'`` (seen in Chromium 156 with viser 1.1.1);
  images and fonts come from ``data:``/``blob:``, and its websocket goes back
  to this origin.  It still loads nothing from elsewhere and may only be
  framed by this origin;
- the API docs (``/docs``): Swagger UI is started by one inline script and
  styles its widgets inline;
- reports (``/api/v1/reports/``): a self-contained page with an inline
  stylesheet and ``data:`` pictures, and no script at all.

A route that sets its own ``Content-Security-Policy`` or ``X-Frame-Options``
keeps it.  Pure ASGI (no ``BaseHTTPMiddleware``): it only edits the headers of
``http.response.start``, so streams and the E-stop are not held up.
"""

from __future__ import annotations

import re

from starlette.types import ASGIApp, Message, Receive, Scope, Send

#: Directives every policy ends with: no framing by other sites, no plugins,
#: no ``<base>`` pointing elsewhere, forms post only here.
_TAIL = "frame-ancestors 'self'; object-src 'none'; base-uri 'self'; form-action 'self'"

CONSOLE_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
    "font-src 'self'; connect-src 'self'{ws}; frame-src 'self'; worker-src 'self'; " + _TAIL
)
SCENE_CSP = (
    "default-src 'self'; script-src 'self' 'unsafe-inline' 'unsafe-eval' 'wasm-unsafe-eval' blob:; "
    "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; font-src 'self' data:; "
    "connect-src 'self'{ws} data: blob:; worker-src 'self' blob:; media-src 'self' data: blob:; "
    + _TAIL
)
DOCS_CSP = (
    "default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data:; connect-src 'self'; " + _TAIL
)
REPORT_CSP = (
    "default-src 'none'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; "
    "font-src 'self' data:; " + _TAIL
)

#: A ``Host`` header safe to write into a policy (a name or IP, and a port).
_HOST = re.compile(r"^(?:[A-Za-z0-9.-]+|\[[0-9A-Fa-f:.]+\])(?::\d{1,5})?$")
_DOCUMENT_TYPES = (b"text/html", b"image/svg+xml")


def policy_for(path: str, host: str | None) -> str:
    """The Content-Security-Policy for a document served at ``path``.

    ``'self'`` covers this origin's websockets in current browsers (CSP 3);
    the same-origin ``ws:``/``wss:`` address is named too, for those that
    predate that rule, when ``host`` is a plain host[:port].
    """
    ws = f" ws://{host} wss://{host}" if host and _HOST.match(host) else ""
    if path == "/scene" or path.startswith("/scene/"):
        return SCENE_CSP.format(ws=ws)
    if path == "/docs" or path.startswith("/docs/"):
        return DOCS_CSP
    if path.startswith("/api/v1/reports/"):
        return REPORT_CSP
    return CONSOLE_CSP.format(ws=ws)


class SecurityHeaders:
    """ASGI middleware adding the headers described in this module's docstring."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                names = {name.lower() for name, _ in headers}
                extra = [(b"x-content-type-options", b"nosniff")]
                extra.append((b"referrer-policy", b"no-referrer"))
                ctype = next((v for n, v in headers if n.lower() == b"content-type"), b"")
                if ctype.lower().startswith(_DOCUMENT_TYPES):
                    host = _request_host(scope)
                    csp = policy_for(str(scope.get("path", "")), host)
                    extra.append((b"content-security-policy", csp.encode("latin-1")))
                    extra.append((b"x-frame-options", b"SAMEORIGIN"))
                headers += [(n, v) for n, v in extra if n not in names]
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)


def _request_host(scope: Scope) -> str | None:
    for name, value in scope.get("headers") or []:
        if name == b"host":
            return str(value.decode("latin-1"))
    return None

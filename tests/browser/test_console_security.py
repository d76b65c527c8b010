"""The console under its Content-Security-Policy, and the CSRF guard, in
Debian's Chromium: the console, the scene iframe and the API docs load with no
policy violation; the console's E-stop goes through; a page on another port of
the same host, which the browser sends the session cookie from (it is
same-site), cannot E-stop a robot."""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import expect

from tests.browser.test_console import browser  # noqa: F401 (fixture)
from tests.conftest import make_settings
from tests.support.live import free_port, live_server

pytestmark = pytest.mark.browser

#: Runs in every frame before its own scripts: records each CSP violation.
CSP_LISTENER = """
window.__csp = [];
document.addEventListener("securitypolicyviolation", (e) => {
  window.__csp.push(`${e.effectiveDirective}: ${e.blockedURI} (${e.sourceFile}:${e.lineNumber})`);
});
"""


def violations(page: Any) -> list[str]:
    """Every violation recorded in the page and its frames."""
    found: list[str] = []
    for frame in page.frames:
        try:
            found += frame.evaluate("window.__csp || []")
        except Exception:  # a frame navigating away: nothing to read
            continue
    return found


@contextmanager
def evil_page(target: str) -> Iterator[str]:
    """A page on another port of 127.0.0.1 that posts the E-stop to ``target``
    with the browser's cookies (a no-cors request needs no CORS permission)."""
    html = f"""<!doctype html><title>waiting</title><script>
fetch("{target}/api/v1/robots/ara/estop", {{method: "POST", credentials: "include",
  mode: "no-cors", headers: {{"Content-Type": "text/plain"}}, body: "{{}}"}})
  .then(() => {{ document.title = "sent"; }}, () => {{ document.title = "failed"; }});
</script>""".encode()

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(html)))
            self.end_headers()
            self.wfile.write(html)

        def log_message(self, *args: Any) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", free_port()), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()


def test_console_scene_and_docs_load_under_the_csp_and_only_the_console_writes(
    browser: Any,  # noqa: F811
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, app):
        store = app.state.services.store

        def estops() -> int:
            return sum(1 for e in store.list_audit("robot") if e.action == "estop")

        # The policy on: no Playwright wait_for_function (it needs eval) in these pages.
        context = browser.new_context(viewport={"width": 1400, "height": 1000}, bypass_csp=False)
        context.add_init_script(CSP_LISTENER)
        page = context.new_page()
        errors: list[str] = []
        console_lines: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.on("console", lambda m: console_lines.append(m.text))
        page.goto(url + "/")
        page.wait_for_selector("#login:not([hidden])")
        page.fill("#login-token", tokens["operator"])
        page.click("#login-form button[type=submit]")
        page.wait_for_selector("#kind option[value='demo.route']", state="attached")
        # The scene iframe: viser's page through the proxy, under its own policy.
        frame = page.wait_for_selector("#scene").content_frame()
        assert frame is not None
        frame.wait_for_selector("canvas", timeout=60_000)
        page.wait_for_timeout(2000)  # its websocket, decoder and first frames
        assert violations(page) == []
        assert not [ln for ln in console_lines if "Content Security Policy" in ln], console_lines

        # Another port of this host: the browser sends the cookie along (same-site),
        # the guard refuses the write.
        with (
            caplog.at_level(logging.WARNING, logger="server.auth"),
            evil_page(url) as evil_url,
        ):
            evil = context.new_page()
            evil.goto(evil_url)
            evil.wait_for_function("document.title !== 'waiting'")
            page.wait_for_timeout(500)
            evil.close()
        assert "refused a cookie-authenticated POST /api/v1/robots/ara/estop" in caplog.text
        assert "CSRF origin check failed" in caplog.text
        assert estops() == 0

        # The console's own E-stop carries the CSRF token from the console's origin.
        page.click("#estop")
        expect(page.locator("#action-msg")).to_contain_text("E-STOP sent", timeout=30_000)
        assert estops() == 1
        assert not errors, errors

        # The API docs render under theirs.
        docs = context.new_page()
        docs.goto(url + "/docs")
        docs.wait_for_selector(".swagger-ui .opblock", timeout=30_000)
        docs.wait_for_timeout(500)
        assert violations(docs) == []
        context.close()

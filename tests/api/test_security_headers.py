"""Security headers (``server.security_headers``): nosniff and no-referrer on
every response, a Content-Security-Policy and framing limit on every page."""

from __future__ import annotations

import re
from pathlib import Path

from server.security_headers import policy_for
from tests.conftest import Api

STATIC = Path(__file__).resolve().parents[2] / "web_static"


def directives(csp: str) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for part in csp.split(";"):
        words = part.split()
        if words:
            out[words[0]] = words[1:]
    return out


def test_every_response_gets_nosniff_and_no_referrer(api: Api) -> None:
    for r in (
        api.client.get("/api/v1/health"),
        api.client.get("/static/console.js"),
        api.client.get("/api/v1/plans"),  # a 401
        api.get("/api/v1/plans"),
        api.client.get("/openapi.json"),
    ):
        assert r.headers["x-content-type-options"] == "nosniff", r.url
        assert r.headers["referrer-policy"] == "no-referrer", r.url
    # JSON is not a document: no page policy on it.
    assert "content-security-policy" not in api.client.get("/api/v1/health").headers


def test_the_console_page_gets_a_strict_policy(api: Api) -> None:
    r = api.client.get("/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    assert r.headers["x-frame-options"] == "SAMEORIGIN"
    csp = directives(r.headers["content-security-policy"])
    assert csp["default-src"] == ["'self'"]
    assert csp["script-src"] == ["'self'"] and csp["style-src"] == ["'self'"]
    assert csp["frame-ancestors"] == ["'self'"]
    assert csp["object-src"] == ["'none'"]
    assert csp["base-uri"] == ["'self'"]
    assert csp["connect-src"][0] == "'self'"
    assert set(csp["connect-src"][1:]) == {"ws://testserver", "wss://testserver"}
    assert not any("unsafe" in w for words in csp.values() for w in words)


def test_the_console_needs_no_inline_script_or_style() -> None:
    """What lets the console's policy stay strict: every script and stylesheet
    is a same-origin file, no element has a style or event-handler attribute."""
    html = (STATIC / "index.html").read_text()
    scripts = re.findall(r"<script\b([^>]*)>", html)
    assert scripts and all(re.search(r'\bsrc="/static/', s) for s in scripts), scripts
    assert "<style" not in html
    assert not re.search(r"\sstyle=", html)
    assert not re.search(r"\son[a-z]+=", html)
    for link in re.findall(r"<link\b[^>]*>", html):
        assert 'href="/static/' in link, link
    for js in STATIC.glob("*.js"):
        text = js.read_text()
        assert 'setAttribute("style"' not in text, js.name
        assert "eval(" not in text and "new Function(" not in text, js.name


def test_docs_and_reports_get_their_own_policies(api: Api) -> None:
    r = api.client.get("/docs")
    assert r.status_code == 200 and r.headers["x-frame-options"] == "SAMEORIGIN"
    csp = directives(r.headers["content-security-policy"])
    # Swagger UI is started by an inline script; it loads nothing from elsewhere.
    assert csp["script-src"] == ["'self'", "'unsafe-inline'"]
    assert csp["default-src"] == ["'self'"] and csp["connect-src"] == ["'self'"]
    assert csp["frame-ancestors"] == ["'self'"] and csp["object-src"] == ["'none'"]
    report = directives(policy_for("/api/v1/reports/pl_1", "h"))
    assert report["default-src"] == ["'none'"] and "script-src" not in report
    assert report["img-src"] == ["'self'", "data:"]


def test_the_scene_policy_allows_what_viser_needs_and_no_other_origin() -> None:
    csp = directives(policy_for("/scene/", "127.0.0.1:8000"))
    assert "'wasm-unsafe-eval'" in csp["script-src"] and "'unsafe-inline'" in csp["script-src"]
    assert "ws://127.0.0.1:8000" in csp["connect-src"]
    assert csp["frame-ancestors"] == ["'self'"] and csp["object-src"] == ["'none'"]
    for words in csp.values():
        assert not any(w in ("*", "http:", "https:", "ws:", "wss:") for w in words), words


def test_a_strange_host_is_not_written_into_a_policy() -> None:
    for host in ("evil; script-src *", "a b", "x'y", ""):
        csp = policy_for("/", host)
        assert "evil" not in csp and "script-src 'self';" in csp
        assert directives(csp)["connect-src"] == ["'self'"]


def test_refusals_by_the_middlewares_carry_the_headers_too(api: Api) -> None:
    c = api.client
    c.post("/api/v1/session", json={"token": api.tokens["operator"]})
    r = c.post("/api/v1/estop", headers={"Origin": "http://evil.example"})
    assert r.status_code == 403
    assert r.headers["x-content-type-options"] == "nosniff"

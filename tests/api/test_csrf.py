"""Cookie-authenticated writes need this server's origin and the double-submit
CSRF token (``server.auth.CsrfGuard``); bearer-token requests are unaffected."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from tests.conftest import Api

OWN = "http://testserver"  # TestClient's origin
EVIL = "http://evil.example"


def signed_in(api: Api, role: str = "operator") -> tuple[TestClient, str]:
    """The API's client signed in as the console is (cookies), and its CSRF token."""
    c = api.client
    r = c.post("/api/v1/session", json={"token": api.tokens[role]})
    assert r.status_code == 200, r.text
    return c, c.cookies["steelpath_csrf"]


def estops(api: Api) -> list[dict[str, Any]]:
    audit = api.get("/api/v1/audit?entity=robot", "viewer").json()
    return [a for a in audit if a["action"] == "estop"]


def test_sign_in_and_the_console_page_set_a_readable_strict_csrf_cookie(api: Api) -> None:
    r = api.client.post("/api/v1/session", json={"token": api.tokens["operator"]})
    cookies = {c.split("=", 1)[0]: c.lower() for c in r.headers.get_list("set-cookie")}
    assert "httponly" in cookies["steelpath_token"]
    csrf = cookies["steelpath_csrf"]
    assert "httponly" not in csrf and "samesite=strict" in csrf and "path=/" in csrf
    first = api.client.cookies["steelpath_csrf"]
    assert len(first) >= 40
    # A fresh one at each sign-in.
    api.client.post("/api/v1/session", json={"token": api.tokens["operator"]})
    assert api.client.cookies["steelpath_csrf"] != first
    # The console page gives a browser without one a cookie (before it signs in) ...
    api.client.cookies.clear()
    page = api.client.get("/")
    assert page.status_code == 200
    assert any(c.startswith("steelpath_csrf=") for c in page.headers.get_list("set-cookie"))
    # ... and not again once it has one.
    again = api.client.get("/")
    assert not any(c.startswith("steelpath_csrf=") for c in again.headers.get_list("set-cookie"))
    # An API read without the session cookie gets none.
    bare = TestClient(api.app).get("/api/v1/health")
    assert "set-cookie" not in bare.headers


def test_cross_origin_cookie_estop_is_refused(api: Api) -> None:
    """The probe: a page on another origin (another port of this host is one)
    posting the E-stop with the operator's cookie is refused, nothing latched."""
    c, csrf = signed_in(api)
    for origin in (EVIL, "http://testserver:8001", "https://testserver", "http://sub.testserver"):
        for path in ("/api/v1/robots/ara/estop", "/api/v1/estop"):
            r = c.post(path, headers={"Origin": origin, "X-CSRF-Token": csrf})
            assert r.status_code == 403, (origin, path, r.text)
            detail = r.json()["detail"]
            assert detail.startswith("CSRF origin check failed") and origin in detail, detail
    assert estops(api) == []
    assert not any(
        r["estop_latched"] for r in api.get("/api/v1/robots", "viewer").json()
    )  # nothing latched


def test_same_origin_cookie_write_needs_the_csrf_token(api: Api) -> None:
    c, csrf = signed_in(api)
    r = c.post("/api/v1/estop", headers={"Origin": OWN})
    assert r.status_code == 403
    assert r.json()["detail"].startswith("CSRF token check failed: the X-CSRF-Token header is")
    r = c.post("/api/v1/estop", headers={"Origin": OWN, "X-CSRF-Token": csrf[:-1] + "x"})
    assert r.status_code == 403 and "does not match" in r.json()["detail"]
    assert estops(api) == []
    # The console's E-stop: its origin and the token.
    r = c.post("/api/v1/estop", headers={"Origin": OWN, "X-CSRF-Token": csrf}, json={})
    assert r.status_code == 200, r.text
    assert len(estops(api)) == 1
    # A cookie-less CSRF header proves nothing: the cookie must be there too.
    c.cookies.delete("steelpath_csrf")
    r = c.post("/api/v1/estop", headers={"Origin": OWN, "X-CSRF-Token": csrf})
    assert r.status_code == 403 and "steelpath_csrf cookie is missing" in r.json()["detail"]


def test_without_an_origin_sec_fetch_site_must_say_same_origin(api: Api) -> None:
    c, csrf = signed_in(api)
    token = {"X-CSRF-Token": csrf}
    r = c.post("/api/v1/estop", headers=token)
    assert r.status_code == 403 and "no Origin header" in r.json()["detail"]
    r = c.post("/api/v1/estop", headers={**token, "Sec-Fetch-Site": "same-site"})
    assert r.status_code == 403 and "'same-site'" in r.json()["detail"]
    r = c.post("/api/v1/estop", headers={**token, "Origin": "null"})
    assert r.status_code == 403 and "Origin is null" in r.json()["detail"]
    assert estops(api) == []
    r = c.post("/api/v1/estop", headers={**token, "Sec-Fetch-Site": "same-origin"})
    assert r.status_code == 200, r.text
    # A page with Referrer-Policy: no-referrer sends "Origin: null" on its own POSTs.
    r = c.post(
        "/api/v1/estop", headers={**token, "Origin": "null", "Sec-Fetch-Site": "same-origin"}
    )
    assert r.status_code == 200, r.text


def test_every_unsafe_method_is_checked_and_reads_are_not(api: Api) -> None:
    c, _ = signed_in(api, "admin")
    for method, path in (
        ("POST", "/api/v1/plans"),
        ("PUT", "/api/v1/robots/ara/connection"),
        ("PATCH", "/api/v1/findings/fi_000000000000"),
        ("DELETE", "/api/v1/plans/pl_000000000000"),
        ("DELETE", "/api/v1/session"),
    ):
        r = c.request(method, path, headers={"Origin": EVIL}, json={})
        assert r.status_code == 403, (method, path, r.status_code)
        assert r.json()["detail"].startswith("CSRF origin check failed")
    assert c.get("/api/v1/plans", headers={"Origin": EVIL}).status_code == 200
    assert c.get("/api/v1/session").status_code == 200  # the DELETE above did not sign out


def test_bearer_requests_are_not_checked(api: Api) -> None:
    """An API client's E-stop works from anywhere, with no CSRF token, even
    beside a session cookie: the bearer token is what authenticates it."""
    c, _ = signed_in(api, "viewer")
    bearer = api.headers("operator")
    r = c.post("/api/v1/robots/ara/estop", headers={"Origin": EVIL, **bearer})
    assert r.status_code == 200, r.text
    r = c.post("/api/v1/estop", headers=bearer, json={"reason": "bearer"})
    assert r.status_code == 200, r.text
    r = c.post("/api/v1/plans", headers={"Origin": EVIL, **bearer}, json={"kind": "demo.route"})
    assert r.status_code == 202, r.text
    assert len(estops(api)) == 2
    # A sign-in without a session cookie is no cookie-authenticated write.
    fresh = TestClient(api.app)
    r = fresh.post("/api/v1/session", json={"token": api.tokens["viewer"]})
    assert r.status_code == 200


def test_a_lost_csrf_cookie_comes_back_on_the_next_read(api: Api) -> None:
    c, old = signed_in(api)
    c.cookies.delete("steelpath_csrf")
    r = c.get("/api/v1/health")
    assert any(h.startswith("steelpath_csrf=") for h in r.headers.get_list("set-cookie"))
    new = c.cookies["steelpath_csrf"]
    assert new and new != old
    r = c.post("/api/v1/estop", headers={"Origin": OWN, "X-CSRF-Token": new})
    assert r.status_code == 200, r.text


def test_behind_a_tls_proxy_the_forwarded_scheme_counts(api: Api) -> None:
    """Caddy (or any proxy) ends TLS and forwards Host and X-Forwarded-Proto."""
    c, csrf = signed_in(api)
    host = {"Host": "steelpath.example", "X-CSRF-Token": csrf}
    r = c.post(
        "/api/v1/estop",
        headers={**host, "Origin": "https://steelpath.example", "X-Forwarded-Proto": "https"},
    )
    assert r.status_code == 200, r.text
    r = c.post("/api/v1/estop", headers={**host, "Origin": "https://steelpath.example"})
    assert r.status_code == 403  # without the header, the connection is plain http
    r = c.post(
        "/api/v1/estop",
        headers={**host, "Origin": "https://steelpath.example:8443", "X-Forwarded-Proto": "https"},
    )
    assert r.status_code == 403

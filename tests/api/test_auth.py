"""Bearer tokens, roles, the first-start admin token and the console session."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from server.app import create_app
from server.auth import hash_token
from tests.conftest import make_settings


def test_no_token_401_everywhere_but_health(api) -> None:
    c = api.client
    assert c.get("/api/v1/health").status_code == 200
    for method, path in (
        ("get", "/api/v1/plans"),
        ("post", "/api/v1/plans"),
        ("get", "/api/v1/clouds"),
        ("get", "/api/v1/kinds"),
        ("get", "/api/v1/events"),
        ("post", "/api/v1/estop"),
        ("get", "/api/v1/audit"),
        ("get", "/api/v1/tokens"),
        ("get", "/scene/"),
    ):
        r = getattr(c, method)(path)
        assert r.status_code == 401, (method, path)
        assert "token" in r.json()["detail"]
        assert r.headers["www-authenticate"] == "Bearer"
    r = c.get("/api/v1/plans", headers={"Authorization": "Bearer sp_wrong"})
    assert r.status_code == 401 and r.json()["detail"] == "invalid or revoked token"


@pytest.mark.parametrize(
    ("method", "path", "body", "needs"),
    [
        ("post", "/api/v1/plans", {"kind": "demo.route", "params": {}}, "operator"),
        ("post", "/api/v1/clouds", {"sample": "demo_plane"}, "operator"),
        ("post", "/api/v1/estop", {}, "operator"),
        ("get", "/api/v1/tokens", None, "admin"),
        ("post", "/api/v1/tokens", {"name": "x", "role": "viewer"}, "admin"),
    ],
)
def test_roles(api, method: str, path: str, body, needs: str) -> None:
    order = ["viewer", "operator", "admin"]
    for role in order:
        kw = {"json": body} if body is not None else {}
        r = getattr(api, method)(path, role, **kw)
        if order.index(role) < order.index(needs):
            assert r.status_code == 403, (role, r.text)
            assert f"needs the {needs} role" in r.json()["detail"]
        else:
            assert r.status_code < 400, (role, r.text)


def test_token_management_stores_only_hashes(api) -> None:
    r = api.post("/api/v1/tokens", "admin", json={"name": "field laptop", "role": "operator"})
    assert r.status_code == 201
    secret, tid = r.json()["token"], r.json()["id"]
    rows = api.services.store.db.query("SELECT hash FROM tokens")
    assert hash_token(secret) in {row["hash"] for row in rows}
    dump = (api.services.store.data_dir / "steelpath.sqlite3").read_bytes()
    assert secret.encode() not in dump
    listed = api.get("/api/v1/tokens", "admin").json()
    assert all("token" not in t and "hash" not in t for t in listed)
    h = {"Authorization": f"Bearer {secret}"}
    assert api.client.get("/api/v1/plans", headers=h).status_code == 200
    assert api.delete(f"/api/v1/tokens/{tid}", "admin").status_code == 200
    assert api.client.get("/api/v1/plans", headers=h).status_code == 401
    r = api.post("/api/v1/tokens", "admin", json={"name": "x", "role": "root"})
    assert r.status_code == 422


def test_first_start_creates_one_admin_token(tmp_path: Path, capsys) -> None:
    token_file = tmp_path / "secrets" / "admin.token"
    settings = make_settings(tmp_path / "var", token_file=token_file)
    with TestClient(create_app(settings)) as c:
        err = capsys.readouterr().err
        secret = token_file.read_text().strip()
        assert secret in err and "shown once" in err
        assert (token_file.stat().st_mode & 0o777) == 0o600
        who = c.get("/api/v1/session", headers={"Authorization": f"Bearer {secret}"}).json()
        assert who["role"] == "admin"
    with TestClient(create_app(settings)):
        assert "admin token" not in capsys.readouterr().err  # printed once only


def test_console_session_cookie(api) -> None:
    c = api.client
    assert c.post("/api/v1/session", json={"token": "sp_not-a-token"}).status_code == 401
    r = c.post("/api/v1/session", json={"token": api.tokens["viewer"]})
    assert r.status_code == 200 and r.json()["role"] == "viewer"
    assert "httponly" in r.headers["set-cookie"].lower()
    assert c.get("/api/v1/plans").status_code == 200  # cookie now authenticates
    assert c.post("/api/v1/estop").status_code == 403
    c.delete("/api/v1/session")
    c.cookies.clear()
    assert c.get("/api/v1/plans").status_code == 401


def test_refusals_say_revoked_or_expired(api) -> None:
    store = api.services.store
    r = api.post("/api/v1/tokens", "admin", json={"name": "t", "role": "viewer"})
    revoked = r.json()
    api.delete(f"/api/v1/tokens/{revoked['id']}", "admin")
    h = {"Authorization": f"Bearer {revoked['token']}"}
    r = api.client.get("/api/v1/plans", headers=h)
    assert r.status_code == 401 and "revoked" in r.json()["detail"]
    r = api.post(
        "/api/v1/tokens", "admin", json={"name": "t2", "role": "viewer", "expires_in_s": 3600}
    )
    assert r.status_code == 201 and r.json()["expires_at"] and r.json()["expired"] is False
    expiring = r.json()
    h = {"Authorization": f"Bearer {expiring['token']}"}
    assert api.client.get("/api/v1/plans", headers=h).status_code == 200
    past = "2000-01-01T00:00:00.000+00:00"
    store.db.query("UPDATE tokens SET expires_at = ? WHERE id = ?", (past, expiring["id"]))
    # An edit behind the store's back is seen once the token cache's entry ends
    # (as a revocation by another process is: tests/api/test_token_cache.py).
    time.sleep(api.services.token_cache.ttl_s + 0.05)
    r = api.client.get("/api/v1/plans", headers=h)
    assert r.status_code == 401 and r.json()["detail"].startswith(f"token expired at {past}")
    assert r.headers["www-authenticate"] == "Bearer"
    listed = {t["id"]: t for t in api.get("/api/v1/tokens", "admin").json()}
    assert listed[expiring["id"]]["expired"] is True
    assert listed[expiring["id"]]["expires_at"] == past

"""OpenAPI docs and the console page are served."""

from __future__ import annotations


def test_openapi_and_docs(api) -> None:
    spec = api.client.get("/openapi.json").json()
    paths = spec["paths"]
    for p in (
        "/api/v1/plans",
        "/api/v1/plans/{plan_id}/approve",
        "/api/v1/clouds",
        "/api/v1/events",
        "/api/v1/estop",
    ):
        assert p in paths, p
    docs = api.client.get("/docs")
    assert docs.status_code == 200 and "swagger" in docs.text.lower()
    # Offline: every asset the page loads is served here, none from a CDN.
    assert "cdn." not in docs.text
    for asset in ("/docs-assets/swagger-ui-bundle.js", "/docs-assets/swagger-ui.css"):
        assert asset in docs.text
        assert api.client.get(asset).status_code == 200


def test_console_page_and_assets(api) -> None:
    page = api.client.get("/")
    assert page.status_code == 200 and 'id="estop"' in page.text
    assert api.client.get("/static/console.js").status_code == 200
    assert api.client.get("/static/console.css").status_code == 200
    assert api.client.get("/static/../server/auth.py").status_code == 404

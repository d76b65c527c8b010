"""One real browser: Debian's Chromium driven by Playwright through the console."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from tests.conftest import make_settings
from tests.support.live import free_port, live_server

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"

pytestmark = pytest.mark.browser

CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


@pytest.fixture(scope="module")
def browser():
    if not Path(CHROMIUM).exists():
        pytest.fail(
            "Debian's chromium is not installed: 'make test' installs it (apt-get install chromium)"
        )
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        yield b
        b.close()


def test_console_plan_approve_and_scene(browser, tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, _app):
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(url + "/")
        # Signed out: the login overlay asks for a token; the E-stop is on screen anyway.
        page.wait_for_selector("#login:not([hidden])")
        assert page.is_visible("#estop")
        page.fill("#login-token", tokens["operator"])
        page.click("#login-form button[type=submit]")
        page.wait_for_selector("#kind option[value='demo.route']", state="attached")
        assert "operator" in page.inner_text("#whoami")

        page.select_option("#kind", "demo.route")
        page.fill("#params", '{"end": "c1"}')
        page.click("#submit-plan")
        # The list is re-rendered on every event: use locators, not element handles.
        page.wait_for_selector("#plans tbody tr[data-state='planned']", timeout=60_000)
        plan_id = page.locator("#plans tbody tr[data-state='planned']").first.get_attribute(
            "data-id"
        )
        page.locator(f"#plans tbody tr[data-id='{plan_id}']").click()
        page.wait_for_selector("#d-checks tr[data-check='route_length']")
        assert page.inner_text("#d-state") == "planned"
        assert "PASS" in page.inner_text("#d-checks")
        page.click("#approve")
        page.wait_for_function("document.querySelector('#d-state').textContent === 'approved'")
        page.wait_for_selector(f"#plans tbody tr[data-id='{plan_id}'][data-state='approved']")
        assert "approve" in (page.text_content("#d-audit") or "")

        # The scene iframe loads viser through the authenticated proxy.
        frame_el = page.wait_for_selector("#scene")
        page.wait_for_function("document.querySelector('#scene').src.endsWith('/scene/')")
        frame = frame_el.content_frame()
        frame.wait_for_selector("canvas", timeout=60_000)

        # The E-stop answers and is recorded.
        page.click("#estop")
        page.wait_for_function(
            "document.querySelector('#action-msg').textContent.includes('E-STOP')"
        )
        ARTIFACTS.mkdir(exist_ok=True)
        page.wait_for_timeout(1500)
        page.screenshot(path=str(ARTIFACTS / "console.png"))
        if os.environ.get("STEELPATH_README_SCREENSHOT"):
            page.screenshot(path=os.environ["STEELPATH_README_SCREENSHOT"])
        assert not errors, errors

    # The approval happened through the page: the server's audit trail says so.
    from server.store import Store

    store = Store(settings.data)
    actions = [e.action for e in store.list_audit("plan", plan_id)]
    assert actions[:2] == ["approve", "finish"]
    assert any(e.action == "estop" for e in store.list_audit("robot"))


def test_api_docs_render_offline(browser, tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "var", port=free_port())
    with live_server(settings) as (url, _tokens, _app):
        page = browser.new_page()
        requests: list[str] = []
        page.on("request", lambda r: requests.append(r.url))
        page.goto(url + "/docs")
        page.wait_for_selector(".swagger-ui .opblock", timeout=30_000)
        assert page.locator(".opblock-summary-path", has_text="/api/v1/plans").count() >= 1
        assert all(r.startswith(url) for r in requests), [
            r for r in requests if not r.startswith(url)
        ]

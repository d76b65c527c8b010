"""One real browser: Debian's Chromium driven by Playwright through the console."""

from __future__ import annotations

import json
import math
import os
import shutil
import time
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import TimeoutError as PlaywrightTimeout

from robots.emulator.robot import check_exactly_once
from tests.conftest import make_settings
from tests.support.live import free_port, live_server

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"

DOCS = Path(__file__).resolve().parents[2] / "docs"

pytestmark = pytest.mark.browser


def screens(page, name: str, focus: str | None = None) -> None:
    """The page at 1280 and 1920 px wide (1000 px tall), ``focus`` scrolled
    into view (else the top of the page), saved as test-artifacts/NAME-WIDTH.png, and into docs/ with
    STEELPATH_DOCS_SCREENSHOTS=1 (how the README's screenshots are made)."""
    size = page.viewport_size
    ARTIFACTS.mkdir(exist_ok=True)
    for width in (1280, 1920):
        page.set_viewport_size({"width": width, "height": 1000})
        page.wait_for_timeout(400)  # let the layout and charts settle
        if focus is not None:
            page.locator(focus).first.scroll_into_view_if_needed()
        else:
            page.evaluate("window.scrollTo(0, 0)")
        path = ARTIFACTS / f"{name}-{width}.png"
        page.screenshot(path=str(path))
        if os.environ.get("STEELPATH_DOCS_SCREENSHOTS"):
            shutil.copy(path, DOCS / path.name)
    page.set_viewport_size(size)


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


class CspBypassingBrowser:
    """The browser, whose new pages and contexts bypass the pages' CSP unless asked
    not to: Playwright's ``wait_for_function`` evaluates its predicate with
    ``eval()`` in the page, which the console's Content-Security-Policy (no
    ``'unsafe-eval'``) forbids.  tests/browser/test_console_security.py checks the
    policy itself, with ``bypass_csp=False``."""

    def __init__(self, browser) -> None:
        self._browser = browser

    def new_page(self, **kw):
        kw.setdefault("bypass_csp", True)
        return self._browser.new_page(**kw)

    def new_context(self, **kw):
        kw.setdefault("bypass_csp", True)
        return self._browser.new_context(**kw)

    def __getattr__(self, name: str):
        return getattr(self._browser, name)


@pytest.fixture(scope="module")
def browser():
    if not Path(CHROMIUM).exists():
        pytest.fail(
            "Debian's chromium is not installed: 'make test' installs it (apt-get install chromium)"
        )
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        yield CspBypassingBrowser(b)
        b.close()


def signed_in(browser, url: str, token: str, height: int = 1000):
    """A new page signed in with ``token``, and the list its page errors go to."""
    page = browser.new_page(viewport={"width": 1400, "height": height})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url + "/")
    page.wait_for_selector("#login:not([hidden])")
    page.fill("#login-token", token)
    page.click("#login-form button[type=submit]")
    return page, errors


def test_console_plan_approve_and_scene(browser, tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, app):
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
        page.fill("#pf-end", "c1")  # the form built from the kind's schema
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

        # Two vertex clicks in the scene (through viser's own callback path)
        # only propose a plan; the console lists it and Accept plans it.
        import types

        scene = app.state.services.scene
        nodes = list(app.state.services.store.get_plan(plan_id).result["nodes"])
        handle = None
        for _ in range(100):
            handle = scene.server.scene.get_handle_by_name("/plan/vertices")
            if handle is not None:
                break
            page.wait_for_timeout(100)
        assert handle is not None
        for name in ("b1", "c0"):
            for entry in handle._impl.click_cb:
                entry.callback(types.SimpleNamespace(instance_index=nodes.index(name), client_id=0))
        assert app.state.services.store.list_plans(parent_id=plan_id) == []
        page.wait_for_selector("#proposals tr[data-proposal]")
        listed = page.inner_text("#proposals")  # in words, not JSON
        assert "start b1 · end c0" in listed and "{" not in listed, listed
        page.click("#proposals tr[data-proposal] button.accept")
        page.wait_for_function(
            f"document.querySelector('#d-title').textContent.includes('revision of {plan_id}')"
        )
        page.wait_for_selector("#proposals tr[data-proposal]", state="detached")
        (child,) = app.state.services.store.list_plans(parent_id=plan_id)
        assert child.params["start"] == "b1" and child.created_by.startswith("live-operator")
        # … and the scene shows the new plan too: one selection in both.
        for _ in range(50):
            if app.state.services.scene.current.get("plan_id") == child.id:
                break
            page.wait_for_timeout(100)
        assert app.state.services.scene.current.get("plan_id") == child.id

        # Measuring.  A real shift-click on viser's canvas reaches the server and
        # the console answers (a first point, or nothing under the cursor).
        assert page.inner_text("#measure-text").startswith("shift-click two points")
        canvas = frame.locator("canvas[data-engine^='three']").first
        box = canvas.bounding_box()
        assert box is not None
        canvas.click(modifiers=["Shift"], position={"x": box["width"] / 2, "y": box["height"] / 2})
        page.wait_for_function(
            "!document.querySelector('#measure-text').textContent.startsWith('shift-click two')"
        )
        # Two picks aimed at drawn vertices (rays straight down onto them): the
        # console shows the server's distance in mm.
        import numpy as np

        xyz = child.result["nodes"]
        for name in ("a0", "c2"):
            scene._on_measure_click(
                types.SimpleNamespace(
                    client_id=99,
                    ray_origin=tuple(np.asarray(xyz[name]) + [0.0, 0.0, 3.0]),
                    ray_direction=(0.0, 0.0, -1.0),
                )
            )
        measured = scene.measurer.public()
        assert measured is not None
        true_mm = 1000 * float(np.linalg.norm(np.subtract(xyz["a0"], xyz["c2"])))
        assert abs(measured["distance_mm"] - true_mm) < 30  # a vertex or the route just above it
        shown = f"{round(measured['distance_mm']):,} mm"
        page.wait_for_function(
            f"document.querySelector('#measure-text').textContent.startsWith({shown!r})"
        )
        assert page.is_visible("#measure-clear")
        screens(page, "console-measure", focus="#measure")

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


def test_viewer_gets_a_read_only_console(browser, tmp_path: Path) -> None:
    """A viewer reads everything but every operator control is disabled with
    the reason on hover, and the E-stop button (operator) is absent; the
    operator's console has them; the scene is shown read-only."""
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, app):
        store = app.state.services.store
        plan_token = tokens["operator"]
        r = httpx.post(
            f"{url}/api/v1/plans",
            json={"kind": "demo.route", "params": {}},
            headers={"Authorization": f"Bearer {plan_token}"},
        )
        pid = r.json()["id"]
        page, errors = signed_in(browser, url, tokens["viewer"])
        page.wait_for_selector("#kind option[value='demo.route']", state="attached")
        assert "viewer" in page.inner_text("#whoami")
        page.wait_for_selector("#readonly:not([hidden])")
        assert not page.is_visible("#estop")
        for sel in ("#submit-plan", "#load-sample", "#upload-cloud"):
            assert page.is_disabled(sel), sel
            assert "operator role" in (page.get_attribute(sel, "title") or ""), sel
        page.wait_for_selector(f"#plans tbody tr[data-id='{pid}'][data-state='planned']")
        page.locator(f"#plans tbody tr[data-id='{pid}']").click()
        page.wait_for_selector("#d-checks tr[data-check='route_length']")
        for sel in ("#approve", "#revise", "#delete", "#cancel", "#dispatch", "#show"):
            assert page.is_disabled(sel), sel
        assert "operator role" in (page.get_attribute("#approve", "title") or "")
        assert store.get_plan(pid).state == "planned"
        # The scene is there, read-only, and says so.
        page.wait_for_function("document.querySelector('#scene').src.endsWith('/scene/')")
        assert page.is_visible("#scene") and not page.is_visible("#measure")
        assert "read-only scene" in page.inner_text("#scene-msg")
        screens(page, "console-viewer")
        assert not errors, errors
        # the operator's console: E-stop on screen, Plan and Approve enabled
        op, _ = signed_in(browser, url, tokens["operator"])
        op.wait_for_selector("#kind option[value='demo.route']", state="attached")
        assert op.is_visible("#estop") and not op.is_visible("#readonly")
        assert op.is_enabled("#submit-plan")
        op.locator(f"#plans tbody tr[data-id='{pid}']").click()
        op.wait_for_selector("#d-checks tr[data-check='route_length']")
        assert op.is_enabled("#approve")


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


def _plan_and_approve(page, params: str) -> str:
    page.select_option("#kind", "demo.route")
    page.click("#tab-json")
    page.fill("#params", params)
    before = set(
        page.eval_on_selector_all("#plans tbody tr", "rows => rows.map(r => r.dataset.id)")
    )
    page.click("#submit-plan")
    # One read that both waits and returns the id: the list re-renders on
    # every event, so a second query could catch it mid-render.
    plan_id = page.wait_for_function(
        "ids => [...document.querySelectorAll('#plans tbody tr[data-state=planned]')]"
        ".map(r => r.dataset.id).find(i => !ids.includes(i)) || null",
        arg=list(before),
        timeout=60_000,
    ).json_value()
    assert isinstance(plan_id, str) and plan_id, plan_id
    page.locator(f"#plans tbody tr[data-id='{plan_id}']").click()
    page.wait_for_function(
        f"document.querySelector('#d-title').textContent.startsWith('{plan_id}')"
    )
    page.wait_for_selector("#d-checks tr[data-check='command_program']")
    page.click("#approve")
    page.wait_for_function("document.querySelector('#d-state').textContent === 'approved'")
    return plan_id


def test_dispatch_to_emulator_then_estop(browser, tmp_path: Path) -> None:
    settings = make_settings(
        tmp_path / "var", port=free_port(), emulators=True, emulator_time_scale=4.0
    )
    with live_server(settings) as (url, tokens, app):
        for name in app.state.services.dispatch.robot_names():
            assert app.state.services.dispatch.wait_connected(name, 30)
        page, errors = signed_in(browser, url, tokens["operator"], height=1100)
        page.wait_for_selector("#robots tr[data-robot='ara'][data-link='ready']", timeout=30_000)

        # A sample cloud, loaded through the page.
        page.select_option("#sample", "demo_plane")
        page.click("#load-sample")
        page.wait_for_function(
            "document.querySelector('#cloud-msg').textContent.includes('5000 points')"
        )

        # Run 1: plan, approve, dispatch to the emulator, watch it complete.
        plan1 = _plan_and_approve(page, '{"end": "b1"}')
        assert "wheels" in (page.text_content("#d-program") or "")
        page.click("#dispatch")
        page.select_option("#dispatch-robot", "ara")
        page.click("#dispatch-confirm")
        page.wait_for_function(
            "document.querySelector('#x-state').textContent === 'completed'", timeout=90_000
        )
        assert "commands" in page.inner_text("#x-progress")
        # Every output of the plan and of its run is a link that downloads with
        # the session (the browser's cookie, no token typed).
        links = page.eval_on_selector_all(
            "#d-outputs a, #x-outputs a", "as => as.map(a => [a.textContent, a.href])"
        )
        assert [label for label, _ in links] == [
            "Report",
            "Report PDF",
            "Plan export",
            "Audit trail",
            "MCAP",
            "ROS 2 bag",
            "Audit trail",
        ], links
        magic = {
            "Report PDF": b"%PDF",
            "Plan export": b"PK",
            "MCAP": b"\x89MCAP",
            "ROS 2 bag": b"PK",
        }
        for label, href in links:
            got = page.context.request.get(href)
            assert got.ok, (label, got.status, got.text()[:200])
            body = got.body()
            if label in magic:
                assert body.startswith(magic[label]), (label, body[:16])
            elif label == "Report":
                assert b"<html" in body[:500].lower(), body[:200]
            else:
                audit = json.loads(body)
                assert audit and all("action" in e for e in audit), audit

        # Run 2: stopped with the E-stop button while the robot moves.
        assert "dispatched as" in page.inner_text("#action-msg")
        plan2 = _plan_and_approve(page, '{"end": "c2"}')
        # The first run's "dispatched as ex_…" is not shown on the new plan.
        assert "dispatched as" not in page.inner_text("#action-msg")
        page.click("#dispatch")
        page.click("#dispatch-confirm")
        page.wait_for_function(
            "document.querySelector('#x-state').textContent === 'running'", timeout=30_000
        )
        # The current command reads as a line with units, not JSON.
        page.wait_for_function("document.querySelector('#x-current').textContent !== '–'")
        current = page.inner_text("#x-current")
        assert current.startswith("wheels: ") and " m/s" in current and "{" not in current, current
        # Abort asks first; dismissed, the robot keeps going.
        page.once("dialog", lambda d: d.dismiss())
        page.click("#x-abort")
        assert page.inner_text("#x-state") == "running"
        # Pause holds the robot where it is; Resume continues from there.
        page.click("#x-pause")
        page.wait_for_function(
            "document.querySelector('#x-state').textContent === 'paused'", timeout=30_000
        )
        assert page.is_enabled("#x-resume") and page.is_disabled("#x-pause")
        page.wait_for_timeout(1500)  # the command in hand when paused may still report
        held = app.state.services.store.list_executions(plan_id=plan2)[0].acked
        page.wait_for_timeout(1500)
        assert app.state.services.store.list_executions(plan_id=plan2)[0].acked == held
        page.click("#x-resume")
        page.wait_for_function(
            "document.querySelector('#x-state').textContent === 'running'", timeout=30_000
        )
        assert not page.is_visible("#audit")  # the audit log is folded by default
        page.click("#estop")
        # The run is interrupted, not ended: the panel says why, when and what next.
        page.wait_for_function(
            "document.querySelector('#x-state').textContent === 'interrupted'", timeout=30_000
        )
        page.wait_for_function(
            "document.querySelector('#x-fault').textContent.includes('E-stop')", timeout=30_000
        )
        why = page.inner_text("#x-fault")
        assert "console E-stop button" in why and " at " in why and "Resume" in why, why
        assert page.is_enabled("#x-resume") and page.is_enabled("#x-abort")
        page.wait_for_function(
            "document.querySelector('#robots tr[data-robot=ara]').textContent.includes('E-STOP latched')",
            timeout=30_000,
        )
        # The red banner names every latched robot and who stopped them.
        page.wait_for_selector("#estop-banner:not([hidden])")
        banner = page.inner_text("#estop-banner")
        assert "E-STOP latched on" in banner and "ara" in banner, banner
        assert "console E-stop button" in banner and "by " in banner, banner
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "console-dispatch.png"), full_page=True)
        screens(page, "console-estop")
        # Clear all asks first: dismissed, nothing changes; accepted, all clear.
        page.once("dialog", lambda d: d.dismiss())
        page.click("#estop-clear-all")
        assert page.is_visible("#estop-banner")
        assert app.state.services.dispatch.robot_status("ara")["estop_latched"]
        page.once("dialog", lambda d: d.accept())
        page.click("#estop-clear-all")
        page.wait_for_selector("#estop-banner", state="hidden", timeout=30_000)
        # Cleared: Resume finishes the run from where the E-stop caught it.
        stopped_at = app.state.services.store.list_executions(plan_id=plan2)[0].acked
        page.wait_for_selector("#robots tr[data-robot=ara][data-link=ready]", timeout=30_000)
        for _ in range(5):  # the robot's own report of the clear may trail the host's by a beat
            page.click("#x-resume")
            try:
                page.wait_for_function(
                    "document.querySelector('#x-state').textContent !== 'interrupted'",
                    timeout=3000,
                )
                break
            except PlaywrightTimeout:
                continue
        page.wait_for_function(
            "document.querySelector('#x-state').textContent === 'completed'", timeout=90_000
        )

        # Run 3: Abort, confirmed, stops the run (no E-stop latched).
        plan3 = _plan_and_approve(page, '{"end": "c1"}')
        page.click("#dispatch")
        page.click("#dispatch-confirm")
        page.wait_for_function(
            "document.querySelector('#x-state').textContent === 'running'", timeout=30_000
        )
        page.once("dialog", lambda d: d.accept())
        page.click("#x-abort")
        page.wait_for_function(
            "document.querySelector('#x-state').textContent === 'aborted'", timeout=30_000
        )
        ex3 = app.state.services.store.list_executions(plan_id=plan3)[0]
        assert ex3.state == "aborted" and ex3.acked < ex3.total
        assert not app.state.services.dispatch.robot_status("ara")["estop_latched"]
        assert page.is_hidden("#estop-banner")
        emulator = app.state.services.emulators["ara"]
        assert emulator.stop_events(), "the emulator never saw the stop"
        assert not errors, errors
        store = app.state.services.store
        ex1, ex2 = (store.list_executions(plan_id=p)[0] for p in (plan1, plan2))
        assert (ex1.state, ex1.acked == ex1.total) == ("completed", True)
        assert (ex2.state, ex2.acked == ex2.total) == ("completed", True)
        assert stopped_at < ex2.total
        log = emulator.execution_log()
        assert check_exactly_once(log, ex2.run_id, ex2.total) == []


def test_plots_have_axes_legend_hover_and_survive_200k_points(browser, tmp_path: Path) -> None:
    """A plan's plots are uPlot charts (served from web_static, no CDN) with
    axis labels and a legend that reads out values under the cursor; a
    200,000-point series (which overflowed the former ``Math.min(...)``)
    draws, decimated for display but keeping its extremes."""
    settings = make_settings(tmp_path / "var", port=free_port())
    with live_server(settings) as (url, tokens, app):
        auth = {"Authorization": f"Bearer {tokens['operator']}"}
        pid = httpx.post(f"{url}/api/v1/plans", json={"kind": "blast", "params": {}}, headers=auth)
        pid = pid.json()["id"]
        page, errors = signed_in(browser, url, tokens["operator"])
        page.wait_for_selector(f"#plans tbody tr[data-id='{pid}'][data-state]", timeout=60_000)
        page.wait_for_selector(
            f"#plans tbody tr[data-id='{pid}'][data-state='planned']", timeout=120_000
        )
        page.locator(f"#plans tbody tr[data-id='{pid}']").click()
        page.wait_for_selector("#d-plots .plot canvas")
        # Metrics read as titles with units, the planning time first, counts as
        # whole numbers, no exponents; past the first eight, folded.
        metrics = app.state.services.store.get_plan(pid).metrics
        assert len(metrics) > 8, metrics
        rows = page.locator("#d-metrics tbody tr[data-metric]")
        assert rows.count() == 8
        first_row = rows.first.inner_text()
        assert first_row.startswith("Planning time") and first_row.endswith(" s"), first_row
        page.click("#d-metrics .metrics-more a")
        assert rows.count() == len(metrics)
        for i in range(rows.count()):
            name = rows.nth(i).get_attribute("data-metric")
            text = rows.nth(i).inner_text()
            assert "e+" not in text and "e-" not in text and "_" not in text, text
            if float(metrics[name]).is_integer():
                assert f"{int(metrics[name]):,}" in text, (name, text)
        plots = app.state.services.store.get_plan(pid).result["plots"]
        first = page.locator("#d-plots .plot").first
        legend = first.locator(".u-legend").inner_text()
        for name in plots[0]["series"]:
            assert name in legend, (name, legend)
        labels = page.evaluate("state.uplots[0].axes.map((a) => a.label)")  # drawn on the canvas
        assert labels == [plots[0]["x_label"], plots[0]["y_label"]]
        box = first.locator(".u-over").bounding_box()
        assert box is not None
        page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.wait_for_function(
            "[...document.querySelectorAll('#d-plots .plot')[0].querySelectorAll('.u-legend .u-value')]"
            ".some((v) => v.textContent.trim() !== '--' && v.textContent.trim() !== '')"
        )
        shown = page.evaluate(
            """() => {
              const n = 200000, x = Array.from({length: n}, (_, i) => i);
              const y = x.map((i) => Math.sin(i / 500) + (i === 123457 ? 50 : 0));
              renderPlots([{title: "big", x, x_label: "sample", y_label: "m", series: {y}}]);
              const u = state.uplots[0];
              return {shown: u.data[0].length, max: u.data[1].reduce((a, b) => (b > a ? b : a), -Infinity)};
            }"""
        )
        assert 0 < shown["shown"] <= 4000
        assert shown["max"] == pytest.approx(50 + math.sin(123457 / 500))  # the spike survives
        assert page.locator("#d-plots .plot canvas").count() == 1
        # A wider window widens the charts with it.
        narrow = page.evaluate("state.uplots[0].width")
        page.set_viewport_size({"width": 1920, "height": 1000})
        page.wait_for_function(f"state.uplots[0].width > {narrow} + 100")
        box_w = page.evaluate("document.querySelector('#d-plots').clientWidth")
        assert abs(page.evaluate("state.uplots[0].width") - (box_w - 10)) <= 2
        ARTIFACTS.mkdir(exist_ok=True)
        page.locator("#d-plots").screenshot(path=str(ARTIFACTS / "console-plots.png"))
        assert not errors, errors


def test_params_form_from_the_kind_schema(browser, tmp_path: Path) -> None:
    """New plan is a form built from GET /kinds' schema: labels with units,
    bounds, enums as selects, booleans as boxes, defaults filled in; a value
    out of bounds is marked at its field and nothing is submitted; the JSON
    tab holds what differs from the defaults and stays in sync both ways; an
    unknown key is named before and by the server (422), and a 422 about a
    field is shown at that field; Revise opens the form on the plan's params."""
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, app):
        page, errors = signed_in(browser, url, tokens["operator"])
        page.wait_for_selector("#kind option[value='ara.navigate']", state="attached")
        store = app.state.services.store

        page.select_option("#kind", "ara.navigate")
        for kind in ("ara.navigate", "ara.inspect", "blast", "cmbot.climb"):
            page.select_option("#kind", kind)  # whole sentences, not a cut first line
            desc = page.inner_text("#kind-desc").strip()
            assert desc.endswith((".", ")", ":")) and len(desc) > 30, (kind, desc)
        page.select_option("#kind", "ara.navigate")
        voxel = page.locator("#params-form .field[data-field='voxel_m']")
        voxel_input = page.locator("#pf-voxel_m")
        # voxel_m is past the first eight scalar fields: folded under "More".
        page.click("#params-form details summary")
        assert voxel.locator(".name").inner_text() == "Voxel (m)"
        assert voxel_input.get_attribute("type") == "number"
        assert voxel_input.get_attribute("max") == "0.1"
        assert voxel_input.input_value() == "0.01"
        assert "[> 0, ≤ 0.1]" in voxel.locator(".hint").inner_text()
        seg = page.locator("#pf-segmentation")
        assert seg.evaluate("e => e.tagName") == "SELECT"
        assert seg.locator("option").all_inner_texts() == ["default", "thesis"]
        # The sample structures are a choice too (the schema lists them).
        assert "warren" in page.locator("#pf-sample option").all_inner_texts()
        assert page.is_checked("#pf-plan_paths")

        # The cloud is picked from the stored clouds, not typed as an id: a
        # sample loaded now appears in the picker, and picking it sets cloud_id.
        picker = page.locator("#pf-cloud_id")
        assert picker.evaluate("e => e.tagName") == "SELECT"
        assert picker.input_value() == ""  # none: the kind's built-in scene
        page.click("#load-sample")
        page.wait_for_function(
            "document.querySelector('#cloud-msg').textContent.includes('stored')"
        )
        (cloud,) = store.list_clouds()
        page.wait_for_selector(f"#pf-cloud_id option[value='{cloud.id}']", state="attached")
        page.select_option("#pf-cloud_id", cloud.id)
        page.click("#tab-json")
        assert json.loads(page.input_value("#params")) == {"cloud_id": cloud.id}
        page.click("#tab-form")
        page.select_option("#pf-cloud_id", "")
        page.click("#tab-json")
        assert json.loads(page.input_value("#params") or "{}") == {}
        page.click("#tab-form")

        n_before = len(store.list_plans())
        voxel_input.fill("")
        voxel_input.press_sequentially("ten")  # text in a number box: "not a number"
        assert "not a number" in voxel.locator(".field-error").inner_text()
        voxel_input.fill("0.5")
        assert "must be ≤ 0.1" in voxel.locator(".field-error").inner_text()
        page.click("#submit-plan")
        assert "fix the marked fields" in page.inner_text("#submit-error")
        assert len(store.list_plans()) == n_before  # nothing was submitted

        voxel_input.fill("0.02")
        page.select_option("#pf-segmentation", label="thesis")
        page.click("#tab-json")
        assert json.loads(page.input_value("#params")) == {
            "voxel_m": 0.02,
            "segmentation": "thesis",
        }
        # JSON → form: a valid edit refills the form, an unknown key is named.
        page.fill("#params", '{"voxel_m": 0.03, "strat": "b1"}')
        assert "'strat'" in page.inner_text("#form-unknown")
        page.click("#tab-form")
        assert voxel_input.input_value() == "0.03"
        assert page.locator("#pf-segmentation").input_value() == '"default"'
        page.click("#submit-plan")  # the server refuses it and names the key
        page.wait_for_function(
            "document.querySelector('#submit-error').textContent.includes('strat')"
        )
        assert not page.inner_text("#submit-error").startswith("HTTP")  # the words, no code
        # Editing the form clears a refusal that was about what was submitted.
        voxel_input.fill("0.03")
        assert page.inner_text("#submit-error") == ""
        assert len(store.list_plans()) == n_before

        # A 422 about a known field is shown at that field.
        page.click("#tab-json")
        page.fill("#params", '{"voxel_m": 0.5}')
        page.click("#submit-plan")
        page.wait_for_selector("#params-form .field.invalid[data-field='voxel_m']")
        assert not page.is_hidden("#params-form")
        assert "0.1" in voxel.locator(".field-error").inner_text()
        assert len(store.list_plans()) == n_before

        # A plan from the form, then Revise opens the form on its params.
        page.select_option("#kind", "demo.route")
        page.fill("#pf-end", "c1")
        page.fill("#pf-max_length_m", "12")
        page.click("#submit-plan")
        page.wait_for_selector("#plans tbody tr[data-state='planned']", timeout=60_000)
        plan = next(p for p in store.list_plans() if p.kind == "demo.route")
        # (stored with the defaults filled in)
        assert (plan.params["end"], plan.params["max_length_m"]) == ("c1", 12)
        assert plan.params["start"] == "a0"
        page.locator(f"#plans tbody tr[data-id='{plan.id}']").click()
        page.wait_for_selector("#d-checks tr[data-check='route_length']")
        page.click("#revise")
        assert page.input_value("#pf-end") == "c1"
        assert page.input_value("#pf-max_length_m") == "12"
        assert "changed" in (
            page.locator("#params-form .field[data-field='end']").get_attribute("class") or ""
        )
        assert page.inner_text("#submit-plan") == f"Revise {plan.id}"
        assert not errors, errors


def test_console_follows_robots_on_the_event_stream(browser, tmp_path: Path) -> None:
    """No polling: after the first load the robots' table is fed by the
    event stream's `robots` snapshots, so an idle console sends no
    GET /robots (the access log once grew ~9,300 lines a session)."""
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, app):
        page, errors = signed_in(browser, url, tokens["viewer"])
        page.wait_for_selector("#robots tbody tr[data-robot]")
        names = set(
            page.eval_on_selector_all("#robots tbody tr", "rs => rs.map(r => r.dataset.robot)")
        )
        assert names == {r["name"] for r in app.state.services.dispatch.robot_statuses()}
        polled: list[str] = []
        page.on("request", lambda r: polled.append(r.url) if "/api/v1/robots" in r.url else None)
        # The table is re-rendered from the stream: mark it and watch it go.
        page.evaluate("document.querySelector('#robots tbody tr').dataset.mark = '1'")
        page.wait_for_function(
            "!document.querySelector('#robots tbody tr[data-mark]')", timeout=10_000
        )
        page.wait_for_timeout(7_000)
        assert polled == [], polled
        assert not errors, errors


def test_a_revision_is_compared_with_its_parent(browser, tmp_path: Path) -> None:
    """The detail of a revision lists what changed against its parent: the
    params, checks that flipped (judged better / worse) and metric changes."""
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, _app):
        h = {"Authorization": f"Bearer {tokens['operator']}"}

        def wait(pid: str) -> dict:
            for _ in range(300):
                p = httpx.get(f"{url}/api/v1/plans/{pid}", headers=h).json()
                if p["state"] not in ("queued", "planning"):
                    return p
                time.sleep(0.1)
            raise AssertionError(f"{pid} still planning")

        r = httpx.post(
            f"{url}/api/v1/plans",
            json={"kind": "demo.route", "params": {"end": "c1", "max_length_m": 0.5}},
            headers=h,
        )
        parent = wait(r.json()["id"])
        assert not next(c for c in parent["checks"] if c["name"] == "route_length")["passed"]
        r = httpx.post(
            f"{url}/api/v1/plans/{parent['id']}/revise",
            json={"params": {"max_length_m": 10}},
            headers=h,
        )
        assert r.status_code in (200, 201, 202), r.text
        child = wait(r.json()["id"])
        page, errors = signed_in(browser, url, tokens["viewer"])
        page.wait_for_selector(f"#plans tbody tr[data-id='{child['id']}']")
        page.locator(f"#plans tbody tr[data-id='{child['id']}']").click()
        page.wait_for_selector("#d-compare:not([hidden])")
        assert parent["id"] in page.inner_text("#d-compare summary")
        check = page.locator("#d-compare tr[data-compare='route_length']")
        assert check.get_attribute("data-verdict") == "better"
        assert "FAIL" in check.inner_text() and "PASS" in check.inner_text()
        param = page.locator("#d-compare tr[data-compare='params.max_length_m']").inner_text()
        assert "0.5" in param and "10" in param
        # The parent itself has nothing to compare with.
        page.locator(f"#plans tbody tr[data-id='{parent['id']}']").click()
        page.wait_for_function(
            f"document.querySelector('#d-title').textContent.startsWith('{parent['id']}')"
        )
        page.wait_for_timeout(300)
        assert page.is_hidden("#d-compare")
        assert not errors, errors


@pytest.mark.parametrize("width", [1280, 1920])
def test_no_horizontal_overflow(browser, tmp_path: Path, width: int) -> None:
    """From 1280 to 1920 px the console fits its width, with a plan, its
    detail, its form and its comparison open (screenshots in the artifacts)."""
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, _app):
        page, errors = signed_in(browser, url, tokens["operator"])
        page.set_viewport_size({"width": width, "height": 1000})
        page.wait_for_selector("#kind option[value='ara.navigate']", state="attached")
        page.select_option("#kind", "ara.navigate")
        page.click("#params-form details summary")  # every field of the longest form
        page.select_option("#kind", "demo.route")
        page.click("#submit-plan")
        page.wait_for_selector("#plans tbody tr[data-state='planned']", timeout=60_000)
        page.locator("#plans tbody tr[data-state='planned']").first.click()
        page.wait_for_selector("#d-checks tr[data-check='route_length']")
        page.click("#revise")
        page.fill("#pf-max_length_m", "11")
        page.click("#submit-plan")
        page.wait_for_function(
            "document.querySelectorAll('#plans tbody tr[data-state=planned]').length >= 2",
            timeout=60_000,
        )
        page.wait_for_selector("#d-compare:not([hidden])")
        overflow = page.evaluate("() => [document.documentElement.scrollWidth, window.innerWidth]")
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / f"console-{width}.png"), full_page=True)
        assert overflow[0] <= overflow[1], f"{width} px: page is {overflow[0]} px wide"
        wide = page.evaluate(
            """() => [...document.querySelectorAll('#app *')]
                .filter(e => e.getBoundingClientRect().right > window.innerWidth + 1)
                .map(e => e.id || e.tagName).slice(0, 5)"""
        )
        assert wide == [], wide
        # Nothing sticks out of its card either (the plans table overflowed its
        # own with the longest state in it).
        page.evaluate(
            "document.querySelector('#plans tbody tr span.state').textContent = 'interrupted'"
        )
        spill = page.evaluate(
            """() => [...document.querySelectorAll('#app .card')].flatMap(card => {
                const edge = card.getBoundingClientRect().right;
                return [...card.querySelectorAll('*')]
                    .filter(e => e.getClientRects().length
                        && e.getBoundingClientRect().right > edge + 1)
                    .map(e => (card.querySelector('h3') || {}).textContent + ': '
                        + (e.id || e.tagName + '.' + e.className));
            }).slice(0, 8)"""
        )
        assert spill == [], spill
        assert not errors, errors


def test_a_late_answer_for_an_earlier_selection_does_not_redraw_the_detail(
    browser, tmp_path: Path
) -> None:
    """The plan event re-selects the selected plan when its state changes; if
    the operator picks another plan while that fetch is out, its late answer
    must not put the older plan back in the detail (CI saw the findings list
    of a re-selected inspection hidden by a blast plan's late detail)."""
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, _app):
        h = {"Authorization": f"Bearer {tokens['operator']}"}
        ids = []
        for end in ("c1", "c2"):
            r = httpx.post(
                f"{url}/api/v1/plans",
                json={"kind": "demo.route", "params": {"end": end}},
                headers=h,
            )
            ids.append(r.json()["id"])
        older, newer = ids
        page, errors = signed_in(browser, url, tokens["viewer"])
        for pid in ids:
            page.wait_for_selector(f"#plans tbody tr[data-id='{pid}'][data-state='planned']")
        held: list = []
        page.route(f"**/api/v1/plans/{older}", lambda route: held.append(route))
        page.evaluate(f"() => {{ select('{older}'); }}")  # not awaited: its answer is held back
        deadline = time.monotonic() + 10
        while not held and time.monotonic() < deadline:
            page.wait_for_timeout(50)
        assert held, "the older selection's fetch never went out"
        page.locator(f"#plans tbody tr[data-id='{newer}']").click()
        page.wait_for_function(
            f"document.querySelector('#d-title').textContent.startsWith('{newer}')"
        )
        held[0].continue_()  # the older answer arrives last
        page.wait_for_timeout(1000)
        assert page.evaluate("state.selected") == newer
        assert page.inner_text("#d-title").startswith(newer)
        assert not errors, errors

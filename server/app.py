"""The FastAPI application: routers by resource, services built in the lifespan."""

from __future__ import annotations

import gc
import logging
import sqlite3
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import fastapi_offline
from fastapi import FastAPI, Request
from fastapi.exception_handlers import request_validation_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import (
    FileResponse,
    HTMLResponse,
    JSONResponse,
    RedirectResponse,
)
from fastapi.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from planners.errors import PlannerError
from server import __version__, log_redaction
from server.asgi_response import send_json
from server.audit_backlog import AuditBacklog
from server.auth import CsrfGuard, bootstrap_admin
from server.captures import router as captures
from server.disk_guard import DiskReserve, disk_full_handler
from server.diskspace import DiskGauge
from server.events import EventBus
from server.jobs import make_job_runner
from server.kinds import registry
from server.lifecycle import IllegalTransitionError
from server.routers import (
    archive,
    clouds,
    events,
    findings,
    foxglove,
    health,
    plans,
    replay,
    reports,
    robots,
    safety,
    tokens,
    webhooks,
)
from server.routers.plans import json_safe
from server.routers.responses import conform_openapi
from server.scene import proxy
from server.security_headers import SecurityHeaders
from server.services import Services
from server.settings import Settings, get_settings
from server.store import NotFoundError, Store
from server.store.cleanup import clean_at_start

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).resolve().parent.parent / "web_static"
API = "/api/v1"


class BodySizeLimit:
    """413 for request bodies over the configured limit, checked while streaming
    (``Content-Length`` can be absent or wrong)."""

    def __init__(self, app: ASGIApp, limit_bytes: Any) -> None:
        self.app = app
        self.limit = limit_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = int(self.limit())
        declared = dict(scope.get("headers") or []).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > limit:
            await self._reject(send, limit)
            return
        seen = 0
        too_big = False

        async def limited() -> Message:
            nonlocal seen, too_big
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > limit:
                    too_big = True
                    raise _TooLarge
            return msg

        try:
            await self.app(scope, limited, send)
        except _TooLarge:
            await self._reject(send, limit)
        except Exception:
            if too_big:
                await self._reject(send, limit)
            else:
                raise

    @staticmethod
    async def _reject(send: Send, limit: int) -> None:
        detail = f"request body exceeds the upload limit of {limit} bytes (STEELPATH_MAX_UPLOAD_MB)"
        await send_json(send, 413, {"detail": detail})


class _TooLarge(Exception):
    pass


def _freeze_startup_objects() -> None:
    """Keep what start-up made (modules, kinds, schemas, the scene) out of every GC pass.

    A full (generation 2) collection walks every tracked object; on a loaded
    2-core machine, with ~200k objects left by start-up, one took 175–380 ms
    and stalled the event loop for that long (measured with ``gc.callbacks``
    during a 250 MB upload beside four streaming robots).  ``gc.freeze()``
    moves them to a permanent generation the collector never scans; objects
    made afterwards are collected as before.
    """
    gc.collect()
    gc.freeze()


def _check_robot_names(settings: Settings) -> None:
    from robots import ROBOT_NAMES

    unknown = sorted(set(settings.emulator_urls) - set(ROBOT_NAMES))
    if unknown:
        raise ValueError(
            f"STEELPATH_EMULATOR_URLS names no robot: {', '.join(unknown)}; "
            f"robots: {', '.join(ROBOT_NAMES)}"
        )


def create_app(settings: Settings | None = None, *, start_scene: bool | None = None) -> FastAPI:
    """Build the app; services start in its lifespan (``TestClient`` as a context manager)."""
    settings = settings or get_settings()
    run_scene = settings.scene_port != 0 if start_scene is None else start_scene
    log_redaction.install()  # no token in uvicorn's or httpx's request lines
    disk = DiskGauge(settings.data, settings.disk_reserve_bytes)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        _check_robot_names(settings)  # before anything starts
        store = Store(settings.data, database_url=settings.database_url)
        # Crash leftovers, before jobs/uploads run; the lock held
        # from here on tells a server starting beside this one what not to touch.
        run_locks = clean_at_start(store)
        bus = EventBus()
        # --- PostgreSQL store: relay this bus's events to and from
        # every other server sharing the database (LISTEN/NOTIFY, server/events_pg.py).
        pg_events = None
        if settings.database_url:
            from server.events_pg import PgEventRelay

            pg_events = PgEventRelay(bus, settings.database_url).start()
        # --- end PostgreSQL event relay
        from server.linkservice.client import new_server_id

        # Several servers may share this store: this one's id, under
        # which its link service holds the leases of the robots it drives and
        # its job runner the plans it plans.
        server_id = new_server_id()
        jobs = make_job_runner(store, bus, settings, server_id)
        services = Services(settings=settings, store=store, events=bus, jobs=jobs)
        services.disk = disk
        services.audit_backlog = AuditBacklog(store)
        jobs.has_room = lambda: disk.room_for(0)
        from server.store.webhooks import WebhookStore
        from server.webhooks import WebhookDispatcher

        services.webhooks = WebhookDispatcher(
            WebhookStore(store.db),
            backoff_s=settings.webhook_backoff_s,
            max_attempts=settings.webhook_max_attempts,
        ).start()
        bus.add_listener(services.webhooks.on_event)
        from server.maintenance import OutcomeRecorder

        services.outcomes = OutcomeRecorder(store, bus)
        bus.add_listener(services.outcomes.on_event)
        services.outcomes.catch_up()  # runs that ended while the service was down
        app.state.services = services
        secret = bootstrap_admin(store, settings.token_file)
        if secret is not None:
            where = f" (also written to {settings.token_file})" if settings.token_file else ""
            print(
                "\n=== SteelPath first start: admin token (shown once; store it safely)"
                f"{where} ===\n{secret}\n",
                file=sys.stderr,
                flush=True,
            )
        registry()
        if run_scene:
            from server.scene.service import SceneService

            def propose(proposal: dict[str, Any]) -> None:
                # A scene interaction is only a proposal (DESIGN §10): publish it
                # for the console; an operator accepts it over REST, which plans.
                bus.publish("proposal", proposal)

            scene = SceneService(store, settings.scene_port, propose, publish=bus.publish)
            scene.start()
            services.scene = scene
            jobs.on_finished.append(scene.plan_finished)
            from server.scene.captures import follow

            follow(scene, bus)
        from robots import ROBOT_NAMES
        from server.linkservice import EmulatorSupervisor, LinkServiceClient
        from server.linkservice.client import server_url
        from server.ownership.keeper import check_lease
        from server.ownership.peers import Peers
        from server.store.ownership import OwnershipStore

        check_lease(settings.robot_lease_s)
        if settings.emulators:
            services.emulators = EmulatorSupervisor(
                settings.data,
                list(ROBOT_NAMES),
                time_scale=settings.emulator_time_scale,
                nice=settings.emulator_nice,
            ).start()
            # So that a server started without emulators reaches these robots.
            OwnershipStore(store.db).record_emulator_urls(services.emulators.urls(), server_id)

        if settings.emulator_urls:
            # Emulators run elsewhere (the scaled Docker set-up): every server reaches them.
            OwnershipStore(store.db).record_emulator_urls(settings.emulator_urls, server_id)

        def kind_robot(kind: str) -> str | None:
            spec = registry().get(kind)
            return spec.robot if spec is not None else None

        dispatch = LinkServiceClient(
            store,
            bus,
            settings,
            scene=services.scene,
            emulators=services.emulators,
            kind_robot=kind_robot,
            server_id=server_id,
        ).start()
        services.dispatch = dispatch
        services.peers = Peers(
            store.db, server_id, server_url(settings), settings.robot_lease_s
        ).start()

        def estop_robots(robot: str | None, reason: str) -> list[str]:
            return dispatch.estop(robot, reason)

        services.estop_handlers.append(estop_robots)
        if settings.foxglove_port:
            from server.foxglove_live import FoxgloveLive

            services.foxglove = FoxgloveLive(store, settings.foxglove_port).start()
            bus.add_listener(services.foxglove.on_event)
        jobs.start()
        _freeze_startup_objects()
        try:
            yield
        finally:
            jobs.shutdown()
            if services.peers is not None:
                services.peers.stop()
            if services.dispatch is not None:
                services.dispatch.shutdown()
            if services.emulators is not None:
                services.emulators.stop()
            if services.scene is not None:
                services.scene.stop()
            if services.foxglove is not None:
                services.foxglove.stop()
            services.webhooks.stop()
            services.outcomes.stop()
            if pg_events is not None:  # PostgreSQL event relay
                pg_events.stop()
            services.audit_backlog.stop()
            store.close()
            run_locks.release()

    app = FastAPI(
        title="SteelPath",
        version=__version__,
        description="Planning server and operator console for steel-bridge robots.",
        lifespan=lifespan,
        docs_url=None,  # served below from local assets: field laptops are offline
        openapi_url="/openapi.json",
    )
    app.add_middleware(BodySizeLimit, limit_bytes=lambda: settings.max_upload_bytes)
    # Outermost of the two: a full disk refuses a write before its body is read.
    app.add_middleware(DiskReserve, gauge=disk)
    # Cookie-authenticated writes need this origin and the CSRF token (server.auth).
    app.add_middleware(CsrfGuard)
    # Outermost: every response, refusals by the middlewares above included.
    app.add_middleware(SecurityHeaders)
    app.state.disk = disk

    # A write that failed for space (SQLite, a file) is a 507 with a message, not a
    # bare 500; any other such error is re-raised to the 500 handler as before.
    app.add_exception_handler(sqlite3.OperationalError, disk_full_handler)
    app.add_exception_handler(OSError, disk_full_handler)
    if settings.database_url:  # PostgreSQL's DiskFull (SQLSTATE 53100); psycopg loads only then
        import psycopg

        app.add_exception_handler(psycopg.Error, disk_full_handler)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        # NaN or Infinity in a body (Python's json parses them) is echoed in the
        # error's input, which strict JSON cannot send: spelled as strings, every
        # route answers its 422 instead of a 500.
        safe = RequestValidationError(json_safe(exc.errors()), body=json_safe(exc.body))
        return await request_validation_exception_handler(request, safe)

    @app.exception_handler(NotFoundError)
    async def _not_found(_: Request, exc: NotFoundError) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=404)

    @app.exception_handler(IllegalTransitionError)
    async def _conflict(_: Request, exc: IllegalTransitionError) -> JSONResponse:
        return JSONResponse(
            {"detail": str(exc), "state": exc.state, "allowed_actions": exc.allowed},
            status_code=409,
        )

    @app.exception_handler(PlannerError)
    async def _planner(_: Request, exc: PlannerError) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=422)

    for r in (
        health.router,
        clouds.router,
        plans.router,
        robots.router,
        events.router,
        safety.router,
        tokens.router,
        webhooks.router,
        findings.router,
        reports.router,
        archive.router,
        replay.router,
        captures.router,
    ):
        app.include_router(r, prefix=API)
    app.include_router(proxy.api_router, prefix=API)
    app.include_router(proxy.proxy_router)
    app.include_router(foxglove.router)  # /foxglove: a websocket at the root, like /scene
    conform_openapi(app)  # every route's error codes in /openapi.json

    @app.get("/", include_in_schema=False)
    def console() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-store"})

    docs_assets = Path(fastapi_offline.__file__).resolve().parent / "static"
    app.mount("/docs-assets", StaticFiles(directory=docs_assets), name="docs-assets")

    @app.get("/docs", include_in_schema=False)
    def docs() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url="/openapi.json",
            title="SteelPath API",
            swagger_js_url="/docs-assets/swagger-ui-bundle.js",
            swagger_css_url="/docs-assets/swagger-ui.css",
            swagger_favicon_url="/docs-assets/favicon.png",
        )

    @app.get("/api", include_in_schema=False)
    def api_root() -> RedirectResponse:
        return RedirectResponse("/docs")

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    return app

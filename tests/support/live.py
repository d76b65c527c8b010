"""A real uvicorn server in a background thread, for CLI and browser tests."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import httpx
import uvicorn

from server.app import create_app
from server.auth import create_token
from server.settings import Settings


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def live_server(settings: Settings) -> Iterator[tuple[str, dict[str, str], object]]:
    """Yields ``(base_url, tokens_by_role, app)`` while the server runs."""
    app = create_app(settings)
    config = uvicorn.Config(
        app,
        host="127.0.0.1",
        port=settings.port,
        log_level="warning",
        ws="websockets-sansio",
        timeout_graceful_shutdown=2,
    )
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    url = f"http://127.0.0.1:{settings.port}"
    deadline = time.monotonic() + 60
    while True:
        try:
            if httpx.get(f"{url}/api/v1/health", timeout=2).status_code == 200:
                break
        except httpx.HTTPError:
            pass
        if time.monotonic() > deadline:
            raise RuntimeError("live server did not start")
        time.sleep(0.1)
    store = app.state.services.store
    tokens = {
        r: create_token(store, f"live-{r}", r, "test")[1] for r in ("viewer", "operator", "admin")
    }
    try:
        yield url, tokens, app
    finally:
        server.should_exit = True
        thread.join(timeout=30)

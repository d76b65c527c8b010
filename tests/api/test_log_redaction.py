"""No token in the logs (``server.log_redaction``): not in uvicorn's access log
(``STEELPATH_ACCESS_LOG=true``), not in its websocket handshake lines."""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path
from typing import Any

import httpx
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect
from websockets.typing import Subprotocol

from server.auth import generate_token
from server.log_redaction import LOGGERS, RedactTokens, install, redact
from tests.support.serve import ServeProcess


def access_record(path: str) -> logging.LogRecord:
    """A record as uvicorn's access logger makes it (h11_impl / httptools_impl)."""
    return logging.LogRecord(
        "uvicorn.access",
        logging.INFO,
        __file__,
        0,
        '%s - "%s %s HTTP/%s" %d',
        ("127.0.0.1:53124", "GET", path, "1.1", 101),
        None,
    )


def test_the_filter_redacts_uvicorns_access_record() -> None:
    secret = generate_token()
    record = access_record(f"/foxglove?token={secret}")
    assert secret in record.getMessage()  # what reached the log before
    assert RedactTokens().filter(record) is True
    line = record.getMessage()
    assert secret not in line
    assert line == '127.0.0.1:53124 - "GET /foxglove?token=REDACTED HTTP/1.1" 101'


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("/foxglove?token=abc&x=1", "/foxglove?token=REDACTED&x=1"),
        ("/a?x=1&access_token=abc", "/a?x=1&access_token=REDACTED"),
        ("/a?TOKEN=abc", "/a?TOKEN=REDACTED"),
        ("/a?key=sp_abcdefghijklmnopqrstuvwxyz", "/a?key=REDACTED"),
        (
            "Authorization: Bearer sp_abcdefghijklmnopqrstuvwxyz012",
            "Authorization: Bearer REDACTED",
        ),
        ("/a?mytoken=1&tokens=2", "/a?mytoken=1&tokens=2"),  # other names stay
        ("GET /api/v1/plans?limit=20", "GET /api/v1/plans?limit=20"),
    ],
)
def test_redact(text: str, expected: str) -> None:
    assert redact(text) == expected


def test_installed_by_the_app_on_every_request_logger(
    make_api: Any, caplog: pytest.LogCaptureFixture
) -> None:
    make_api()
    for name in LOGGERS:
        assert sum(isinstance(f, RedactTokens) for f in logging.getLogger(name).filters) == 1
    install()  # idempotent: a second app adds no second filter
    assert (
        sum(isinstance(f, RedactTokens) for f in logging.getLogger("uvicorn.access").filters) == 1
    )
    secret = generate_token()
    with caplog.at_level(logging.INFO, logger="uvicorn.error"):
        logging.getLogger("uvicorn.error").info(
            '%s - "WebSocket %s" [accepted]', "127.0.0.1:1", f"/foxglove?token={secret}"
        )
    assert secret not in caplog.text and "token=REDACTED" in caplog.text


def test_a_served_app_logs_no_token(tmp_path: Path) -> None:
    """``steelpath serve`` with the access log on, at the default ``info``
    level: the documented Foxglove URL, a websocket handshake and a query
    string holding a token never show the token."""
    data = tmp_path / "var"
    data.mkdir()
    server = ServeProcess(data, "logs", access_log="true", log_level="info")
    try:
        # Not the first-start admin token: the server prints that one once, by design.
        token = server.post("/tokens", {"name": "foxglove", "role": "viewer"}, status=201)["token"]
        ws_url = server.url.replace("http://", "ws://")
        with (
            contextlib.suppress(InvalidStatus, OSError),
            connect(
                f"{ws_url}/foxglove?token={token}", subprotocols=[Subprotocol("foxglove.sdk.v1")]
            ),
        ):
            pass  # the live Foxglove server is off: 503 at the handshake
        httpx.get(f"{server.url}/foxglove?token={token}", timeout=10)
        r = httpx.get(f"{server.url}/api/v1/health?access_token={token}&key={token}", timeout=10)
        assert r.status_code == 200
    finally:
        server.stop()
    log = Path(server.log.name).read_text()
    assert '"GET /api/v1/health?access_token=REDACTED&key=REDACTED HTTP/1.1" 200' in log, log
    assert "/foxglove?token=REDACTED" in log, log
    assert "WebSocket /foxglove?token=REDACTED" in log, log
    assert token not in log

"""Keep tokens out of the logs.

Foxglove can authenticate only through its URL (``/foxglove?token=…``), and
uvicorn logs request paths with their query strings: every request in its
access log (``STEELPATH_ACCESS_LOG=true``), and every websocket handshake
(``"WebSocket /foxglove?token=…" [accepted]``) in its error log at ``info``,
the default level.  :class:`RedactTokens` rewrites a record's message and
arguments before any handler formats them:

- the value of a ``token`` or ``access_token`` query parameter;
- any other parameter's value that is a SteelPath token (``sp_…``);
- a SteelPath token anywhere else in the text (a bearer header, say)

become ``REDACTED``.  :func:`install` puts it on uvicorn's loggers and on
``httpx``'s (the scene proxy and peer forwarding log each request's URL).
Filters on a logger survive uvicorn's ``dictConfig`` (it replaces handlers
only), so installing it when the app is built is enough.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from typing import Any

from server.auth import TOKEN_PREFIX

REDACTED = "REDACTED"
#: Loggers whose records carry request URLs.
LOGGERS = ("uvicorn.access", "uvicorn.error", "uvicorn", "httpx")

_SECRET_PARAM = re.compile(r"(?i)((?:^|[?&;\s\"'])(?:access_token|token)=)[^&;#\s\"']*")
_TOKEN_VALUE = re.compile(rf"((?:^|[?&;])[^=&;#\s\"']+=){re.escape(TOKEN_PREFIX)}[^&;#\s\"']*")
_BARE_TOKEN = re.compile(rf"\b{re.escape(TOKEN_PREFIX)}[A-Za-z0-9_-]{{16,}}")


def redact(text: str) -> str:
    """``text`` with token-bearing query values and SteelPath tokens replaced."""
    if "=" not in text and TOKEN_PREFIX not in text:
        return text  # the common case: nothing to look at
    text = _SECRET_PARAM.sub(rf"\g<1>{REDACTED}", text)
    text = _TOKEN_VALUE.sub(rf"\g<1>{REDACTED}", text)
    return _BARE_TOKEN.sub(REDACTED, text)


def _redact_arg(value: Any) -> Any:
    # Only strings: numbers must stay numbers for the message's %d.
    return redact(value) if isinstance(value, str) else value


class RedactTokens(logging.Filter):
    """A filter that redacts tokens in a record's message and string arguments."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.msg, str):
            record.msg = redact(record.msg)
        args = record.args
        if isinstance(args, tuple):
            record.args = tuple(_redact_arg(a) for a in args)
        elif isinstance(args, Mapping):
            record.args = {k: _redact_arg(v) for k, v in args.items()}
        return True


def install(names: tuple[str, ...] = LOGGERS) -> None:
    """Add one :class:`RedactTokens` to each named logger (once, however often called)."""
    for name in names:
        logger = logging.getLogger(name)
        if not any(isinstance(f, RedactTokens) for f in logger.filters):
            logger.addFilter(RedactTokens())

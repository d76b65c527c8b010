"""The service objects one running app holds, shared by routers via a dependency."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from fastapi import Request

from server.events import EventBus
from server.jobs import JobRunner
from server.settings import Settings
from server.store import Store


@dataclass
class Services:
    settings: Settings
    store: Store
    events: EventBus
    jobs: JobRunner
    scene: Any = None  # server.scene.service.SceneService when the scene runs
    dispatch: Any = None  # server.linkservice.LinkServiceClient once robots are wired
    emulators: Any = None  # server.linkservice.EmulatorSupervisor when built-in emulators run
    # A handler may return the robots it reached (the link service's does).
    estop_handlers: list[Callable[[str | None, str], Any]] = field(default_factory=list)
    token_cache: Any = None  # server.auth.TokenCache, made on first use
    webhooks: Any = None  # server.webhooks.WebhookDispatcher
    outcomes: Any = None  # server.maintenance.OutcomeRecorder
    foxglove: Any = None  # server.foxglove_live.FoxgloveLive (STEELPATH_FOXGLOVE_PORT)
    peers: Any = None  # server.ownership.peers.Peers: the other servers sharing the store
    audit_backlog: Any = (
        None  # server.audit_backlog.AuditBacklog: safety records kept until written
    )
    disk: Any = None  # server.diskspace.DiskGauge: free space on the data directory


async def get_services(request: Request) -> Services:
    # async: a plain attribute read must not cost a worker-thread hop per request.
    return request.app.state.services

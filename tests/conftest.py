"""Shared fixtures: an app per test on its own data directory, tokens per role."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from hypothesis import settings as hypothesis_settings

from server.app import create_app
from server.auth import create_token
from server.settings import Settings

# Property tests are deterministic by default (the same examples every run,
# so CI cannot go red on a lucky draw); HYPOTHESIS_PROFILE=explore draws new
# examples each run to hunt for counterexamples locally.
hypothesis_settings.register_profile("deterministic", derandomize=True, database=None)
hypothesis_settings.register_profile("explore", derandomize=False)
hypothesis_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))

#: Tests that start a server, a link service or emulator processes: marked
#: ``integration``, so ``make test-fast`` (the edit loop) can leave them to
#: ``make test``.
INTEGRATION_PATHS = (
    "tests/api/",
    "tests/cli/",
    "tests/emulator/",
    "tests/linkservice/",
    "tests/switching/test_api_switch.py",
    "tests/navigation/test_kind_ara_navigate.py",
    "tests/inspection/test_kind_ara_inspect.py",
    "tests/docker/",
)
_ROOT = Path(__file__).resolve().parents[1]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        rel = Path(str(item.path)).resolve().relative_to(_ROOT).as_posix()
        if rel.startswith(INTEGRATION_PATHS):
            item.add_marker(pytest.mark.integration)


SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
if not SHARED_DATA.is_dir():  # CI clones beside ../shared; a checkout elsewhere may set this
    SHARED_DATA = Path(os.environ.get("STEELPATH_SHARED_DATA", "/work/shared/data"))


@dataclass
class Api:
    """A TestClient plus a token per role."""

    client: TestClient
    tokens: dict[str, str]
    app: Any

    def headers(self, role: str = "operator") -> dict[str, str]:
        return {"Authorization": f"Bearer {self.tokens[role]}"}

    def get(self, path: str, role: str = "operator", **kw: Any) -> Any:
        headers = {**self.headers(role), **kw.pop("headers", {})}
        return self.client.get(path, headers=headers, **kw)

    def post(self, path: str, role: str = "operator", **kw: Any) -> Any:
        headers = {**self.headers(role), **kw.pop("headers", {})}
        return self.client.post(path, headers=headers, **kw)

    def put(self, path: str, role: str = "operator", **kw: Any) -> Any:
        headers = {**self.headers(role), **kw.pop("headers", {})}
        return self.client.put(path, headers=headers, **kw)

    def patch(self, path: str, role: str = "operator", **kw: Any) -> Any:
        headers = {**self.headers(role), **kw.pop("headers", {})}
        return self.client.patch(path, headers=headers, **kw)

    def delete(self, path: str, role: str = "operator", **kw: Any) -> Any:
        headers = {**self.headers(role), **kw.pop("headers", {})}
        return self.client.delete(path, headers=headers, **kw)

    @property
    def services(self) -> Any:
        return self.app.state.services

    def submit(
        self, kind: str, params: dict[str, Any] | None = None, role: str = "operator"
    ) -> dict[str, Any]:
        r = self.post("/api/v1/plans", role, json={"kind": kind, "params": params or {}})
        assert r.status_code == 202, r.text
        return r.json()

    def wait(
        self, plan_id: str, timeout: float = 120.0, until: tuple[str, ...] = ()
    ) -> dict[str, Any]:
        """Poll until the plan leaves queued/planning (or reaches one of ``until``)."""
        deadline = time.monotonic() + timeout
        while True:
            plan = self.get(f"/api/v1/plans/{plan_id}").json()
            if (until and plan["state"] in until) or (
                not until and plan["state"] not in ("queued", "planning")
            ):
                return plan
            if time.monotonic() > deadline:
                raise AssertionError(
                    f"plan {plan_id} still {plan['state']} after {timeout}s: {plan}"
                )
            time.sleep(0.02)


def make_settings(data: Path, **kw: Any) -> Settings:
    base: dict[str, Any] = {"data": data, "job_mode": "thread", "scene_port": 0, "emulators": False}
    base.update(kw)
    return Settings(**base)


@pytest.fixture
def make_api(tmp_path: Path) -> Iterator[Any]:
    """Factory: ``make_api(**settings)`` → a started :class:`Api` (closed after the test)."""
    stack: list[TestClient] = []

    def factory(data: Path | None = None, **kw: Any) -> Api:
        settings = make_settings(data or tmp_path / "var", **kw)
        app = create_app(settings)
        client = TestClient(app)
        client.__enter__()
        stack.append(client)
        store = app.state.services.store
        tokens = {
            role: create_token(store, f"test-{role}", role, "test")[1]
            for role in ("viewer", "operator", "admin")
        }
        return Api(client, tokens, app)

    yield factory
    for client in reversed(stack):
        client.__exit__(None, None, None)


@pytest.fixture
def api(make_api: Any) -> Api:
    return make_api()

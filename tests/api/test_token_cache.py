"""The in-process token cache: a hit needs no store read, and never outlives a refusal.

What must hold: a revocation through this process's store refuses the token
on the very next request; one made by another process (the CLI opens its own
``Store``) within the cache's ``ttl_s``; an expired token is refused on a hit;
a refused token is not cached.  The API-level check runs through a real app.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from server.auth import TokenCache, TokenRefused, create_token
from server.store import Store


class CountingStore:
    """A Store whose token reads are counted (the cache's whole point is fewer of them)."""

    def __init__(self, store: Store) -> None:
        self._store = store
        self.reads = 0

    def lookup_token(self, token_hash: str) -> Any:
        self.reads += 1
        return self._store.lookup_token(token_hash)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._store, name)


@pytest.fixture
def store(tmp_path: Path) -> Iterator[Store]:
    s = Store(tmp_path / "var")
    yield s
    s.close()


def test_a_hit_reads_nothing_and_a_local_revocation_refuses_at_once(store: Store) -> None:
    counting = CountingStore(store)
    tid, secret = create_token(store, "op", "operator", "test")
    cache = TokenCache(counting, ttl_s=60.0)  # type: ignore[arg-type]
    assert cache.hit(secret) is None
    first = cache.resolve(secret)
    assert (first.token_id, first.role) == (tid, "operator")
    assert counting.reads == 1
    for _ in range(5):
        assert cache.hit(secret) == first
    assert counting.reads == 1  # hits read nothing
    store.revoke_token(tid, "test")
    assert cache.hit(secret) is None  # the epoch moved: dropped, despite the 60 s ttl
    with pytest.raises(TokenRefused, match="revoked"):
        cache.resolve(secret)


def test_a_revocation_by_another_process_is_seen_after_the_ttl(store: Store) -> None:
    tid, secret = create_token(store, "op", "operator", "test")
    cache = TokenCache(store, ttl_s=0.2)
    cache.resolve(secret)
    other = Store(store.data_dir)  # as `steelpath token revoke` opens it
    try:
        other.revoke_token(tid, "cli")
    finally:
        other.close()
    assert store.token_epoch == 0  # this process's store never saw the revocation
    time.sleep(0.25)
    assert cache.hit(secret) is None
    with pytest.raises(TokenRefused, match="revoked"):
        cache.resolve(secret)


def test_an_expired_token_is_refused_on_a_hit(store: Store) -> None:
    _, secret = create_token(store, "short", "viewer", "test", expires_in_s=0.3)
    cache = TokenCache(store, ttl_s=60.0)
    assert cache.resolve(secret).role == "viewer"
    assert cache.hit(secret) is not None
    time.sleep(0.35)
    assert cache.hit(secret) is None
    with pytest.raises(TokenRefused, match="expired"):
        cache.resolve(secret)


def test_refusals_are_not_cached_and_the_size_is_bounded(store: Store) -> None:
    counting = CountingStore(store)
    cache = TokenCache(counting, ttl_s=60.0, max_entries=3)  # type: ignore[arg-type]
    for _ in range(3):
        with pytest.raises(TokenRefused):
            cache.resolve("sp_not-a-token")
        assert cache.hit("sp_not-a-token") is None
    assert counting.reads == 3
    secrets = [create_token(store, f"t{i}", "viewer", "test")[1] for i in range(5)]
    for s in secrets:
        cache.resolve(s)
    assert len(cache._entries) <= 3
    assert cache.hit(secrets[-1]) is not None


def test_api_refuses_a_revoked_token_on_the_next_request(api: Any) -> None:
    headers = {"Authorization": f"Bearer {api.tokens['viewer']}"}
    assert api.client.get("/api/v1/plans", headers=headers).status_code == 200
    assert api.client.get("/api/v1/plans", headers=headers).status_code == 200  # a cache hit
    store = api.app.state.services.store
    (rec,) = [t for t in store.list_tokens() if t.name == "test-viewer"]
    store.revoke_token(rec.id, "test")
    r = api.client.get("/api/v1/plans", headers=headers)
    assert r.status_code == 401
    assert "revoked" in r.json()["detail"]

"""A server start (``steelpath serve``, every server a test spawns, a restart
after a crash) imports the app: the libraries only some requests need load
with their first such request."""

from __future__ import annotations

from tests.support.imports import loaded_by

#: matplotlib draws report pictures (0.3 s to import); OMPL, trimesh and viser
#: come with the planners' workers and the scene.
DEFERRED = ("matplotlib", "ompl", "trimesh", "viser")


def test_the_app_imports_without_the_libraries_few_requests_need() -> None:
    loaded = loaded_by("server.app", DEFERRED)
    assert loaded == [], f"importing server.app imports {' '.join(loaded)}"

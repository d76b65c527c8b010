"""The capture tests that touch the store, again with PostgreSQL as the store:
the migration's table, the bounds, the REST answers and the exports."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.api.test_captures import (  # noqa: F401
    test_a_capture_fed_at_the_link_service_is_stored_listed_and_served,
    test_a_full_disk_refuses_a_capture_and_leaves_no_file,
    test_malformed_captures_are_refused,
    test_past_its_bounds_a_capture_is_refused_and_the_execution_says_why,
)
from tests.api.test_recording_captures import (  # noqa: F401
    test_captures_export_to_a_ros2_bag_with_their_tf,
    test_captures_export_to_mcap_in_the_camera_frame_placed_by_tf,
)
from tests.support.postgres import PgServer, postgres_server  # noqa: F401


@pytest.fixture
def make_api(
    make_api: Callable[..., Any],
    postgres_server: PgServer,  # noqa: F811
    tmp_path: Path,
) -> Any:
    """conftest's ``make_api`` with ``database_url`` set: one database per data directory."""
    databases: dict[Path, str] = {}

    def factory(data: Path | None = None, **kw: Any) -> Any:
        key = Path(data or tmp_path / "var").resolve()
        if key not in databases:
            databases[key] = postgres_server.new_database(migrated=True)
        kw.setdefault("database_url", databases[key])
        return make_api(data, **kw)

    return factory

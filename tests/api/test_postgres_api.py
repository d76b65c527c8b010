"""The API's lifecycle tests again, with PostgreSQL as the store.

The tests below are the SQLite suite's own functions, imported and collected
here a second time; this module's ``make_api`` gives every server a
PostgreSQL database (a real server, :mod:`tests.support.postgres`): one per
data directory, so a restart on the same directory finds the same database
and a second server (an archive's importer) has one of its own.  Every test
of the plan API and lifecycle (``test_plans``), restart (``test_restart``)
and dispatch (``test_dispatch``: runs, refusals, pause/resume/abort, E-stop,
a server restart in the middle of a run, the link service process on the
same database); besides them, chosen to cover what the store does: archive export/import
(generic row reads and writes, column lists, rollback), findings with photos,
a webhook delivery surviving a restart, tokens.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.api.test_archive import (  # noqa: F401
    small_archive,
    test_a_failure_while_writing_rolls_back_rows_and_files,
    test_a_real_run_with_findings_exports_and_imports_on_another_server,
    test_the_source_cloud_travels_with_its_plan,
)
from tests.api.test_dispatch import (  # noqa: F401
    dapi,
    test_an_estopped_run_can_be_aborted,
    test_compiled_program_is_stored_and_checked,
    test_dispatch_refusals,
    test_dispatch_runs_to_completion_exactly_once,
    test_estop_stops_the_run_and_it_resumes_once_cleared,
    test_estop_while_reconnecting_reaches_the_robot_when_it_returns,
    test_pause_resume_abort,
    test_robots_panel,
    test_server_restart_mid_run_resumes_without_loss,
)
from tests.api.test_findings import (  # noqa: F401
    fapi,
    test_a_finding_on_a_face_is_checked_listed_edited_and_withdrawn,
    test_photos_are_checked_by_content_and_served,
)
from tests.api.test_plans import (  # noqa: F401
    test_approve_and_illegal_transitions,
    test_bad_requests,
    test_cancel_queued_and_running,
    test_delete_rules,
    test_events_stream_replays_plan_changes,
    test_every_kind_forbids_unknown_params_keys,
    test_failed_check_rejects_and_blocks_approval,
    test_kinds_endpoint,
    test_legacy_rows_with_unknown_keys_still_load_run_and_revise,
    test_list_filters_and_pagination,
    test_listing_is_a_summary_with_the_program_length,
    test_misspelt_params_key_is_refused_naming_it,
    test_nested_params_models_forbid_unknown_keys,
    test_planner_error_fails_plan_and_server_keeps_serving,
    test_progress_is_visible_while_planning,
    test_revision_creates_linked_plan_and_keeps_parent,
    test_submit_plan_and_read_it_back,
)
from tests.api.test_restart import (  # noqa: F401
    test_restart_keeps_plans_clouds_executions_audit,
    test_restart_requeues_interrupted_planning,
)
from tests.api.test_token_lifetime import test_token_expiry_validation  # noqa: F401
from tests.api.test_webhooks import test_a_pending_delivery_survives_a_restart  # noqa: F401
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


def test_every_plans_restart_and_dispatch_test_runs_here_too() -> None:
    """A test added to those modules must be added above, or it would run on SQLite only."""
    import tests.api.test_dispatch as dispatch_tests
    import tests.api.test_plans as plans_tests
    import tests.api.test_restart as restart_tests

    here = {n for n in globals() if n.startswith("test_")}
    for module in (plans_tests, restart_tests, dispatch_tests):
        missing = {n for n in vars(module) if n.startswith("test_")} - here
        assert not missing, f"{module.__name__}: {sorted(missing)} not run on PostgreSQL"

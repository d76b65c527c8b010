"""A real PostgreSQL server for the tests, from Debian's ``postgresql`` package.

:func:`postgres_server` (session scope) runs ``initdb`` in a temporary
directory and starts the server on 127.0.0.1 at a free port, its unix socket
in that directory, ``trust`` authentication, durability off (``fsync``,
``synchronous_commit``: a test database needs no crash safety, and this makes
it several times faster); ``pg_ctl stop -m immediate`` at the end.  PostgreSQL
refuses to run as root, so as root (CI) the directory is handed to the
``postgres`` system user the package creates and the tools run through
``runuser -u postgres --``; as anyone else they run as that user.

:func:`pg_url` gives each test a database of its own (``CREATE DATABASE``,
dropped afterwards).  Without PostgreSQL binaries the tests that need them
are skipped, saying why.

Import the fixtures into a test module::

    from tests.support.postgres import pg_url, postgres_server  # noqa: F401
"""

from __future__ import annotations

import glob
import os
import secrets
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

SUPERUSER = "steelpath"


def find_bin_dir() -> Path | None:
    """The newest ``/usr/lib/postgresql/<version>/bin`` holding ``initdb`` and ``pg_ctl``."""
    found = [
        Path(d)
        for d in glob.glob("/usr/lib/postgresql/*/bin")
        if (Path(d) / "initdb").is_file() and (Path(d) / "pg_ctl").is_file()
    ]
    if not found:
        return None
    return max(found, key=lambda d: int(d.parent.name) if d.parent.name.isdigit() else 0)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class PgServer:
    """A running test server: ``url(db)`` connects to database ``db`` over TCP."""

    port: int
    root: Path
    bin_dir: Path
    migrated_template: str = ""

    def url(self, dbname: str = "postgres") -> str:
        return f"postgresql://{SUPERUSER}@127.0.0.1:{self.port}/{dbname}"

    def admin(self, sql: str) -> None:
        """Run ``sql`` outside a transaction (``CREATE``/``DROP DATABASE``)."""
        import psycopg

        with psycopg.connect(self.url(), autocommit=True) as conn:
            conn.execute(sql.encode())

    def new_database(self, *, migrated: bool = False) -> str:
        """A fresh database, empty or (``migrated``) already at the current schema
        (a copy of a template migrated once: an app's start then skips the ~0.2–0.5 s
        of running every migration); its URL."""
        name = f"t_{secrets.token_hex(6)}"
        template = self._migrated_template() if migrated else "template1"
        # FILE_COPY: with fsync off its checkpoint is cheap, and it measured
        # faster than PostgreSQL 15's default WAL_LOG for a small template.
        self.admin(f"CREATE DATABASE {name} TEMPLATE {template} STRATEGY FILE_COPY")
        return self.url(name)

    def _migrated_template(self) -> str:
        if not self.migrated_template:
            from server.store.postgres import PostgresDatabase

            name = "steelpath_migrated"
            self.admin(f"CREATE DATABASE {name} STRATEGY FILE_COPY")
            PostgresDatabase(self.url(name)).close()  # no connection left: copyable
            self.migrated_template = name
        return self.migrated_template

    def drop_database(self, url: str) -> None:
        name = url.rsplit("/", 1)[-1]
        self.admin(f"DROP DATABASE IF EXISTS {name} WITH (FORCE)")


def _runner() -> list[str]:
    """How to run the PostgreSQL tools: as ``postgres`` when we are root."""
    return ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[PgServer]:
    bin_dir = find_bin_dir()
    if bin_dir is None:
        pytest.skip(
            "no PostgreSQL binaries under /usr/lib/postgresql/*/bin "
            "(apt-get install postgresql, or `make system-test-deps`)"
        )
    root = Path(tempfile.mkdtemp(prefix="steelpath-pg-"))
    run_as = _runner()
    if run_as:
        shutil.chown(root, "postgres", "postgres")
    data, log = root / "data", root / "server.log"
    port = _free_port()
    env = {**os.environ, "LC_ALL": "C.UTF-8", "TZ": "UTC"}
    try:
        subprocess.run(
            [*run_as, str(bin_dir / "initdb"), "-D", str(data), "-U", SUPERUSER]
            + ["--auth=trust", "-E", "UTF8", "--no-sync", "--no-instructions"],
            check=True,
            capture_output=True,
            env=env,
            cwd=root,
        )
        opts = (
            f"-c listen_addresses=127.0.0.1 -p {port} -k {root} -c fsync=off "
            "-c synchronous_commit=off -c full_page_writes=off -c max_connections=200"
        )
        started = time.monotonic()
        subprocess.run(
            [*run_as, str(bin_dir / "pg_ctl"), "-D", str(data), "-o", opts, "-l", str(log)]
            + ["-w", "-t", "60", "start"],
            check=True,
            capture_output=True,
            env=env,
            cwd=root,
        )
    except subprocess.CalledProcessError as exc:
        tail = log.read_text(errors="replace")[-2000:] if log.exists() else ""
        shutil.rmtree(root, ignore_errors=True)
        raise RuntimeError(
            f"could not start the test PostgreSQL: {exc.stderr.decode(errors='replace')}{tail}"
        ) from exc
    server = PgServer(port=port, root=root, bin_dir=bin_dir)
    print(f"test PostgreSQL on 127.0.0.1:{port} up in {time.monotonic() - started:.2f} s")
    try:
        yield server
    finally:
        subprocess.run(
            [*run_as, str(bin_dir / "pg_ctl"), "-D", str(data), "-m", "immediate", "stop"],
            capture_output=True,
            env=env,
            cwd=root,
        )
        shutil.rmtree(root, ignore_errors=True)


@pytest.fixture
def pg_url(postgres_server: PgServer) -> Iterator[str]:
    """A database of this test's own on the session's server."""
    url = postgres_server.new_database()
    yield url
    postgres_server.drop_database(url)

"""A Docker daemon for the tests, and stand-ins for the base images it cannot pull.

The compose file (``docker/compose.yml``) names three images from Docker Hub:
``python:3.11-slim-bookworm`` (the product image's base), ``postgres:15-bookworm``
and ``caddy:2``.  Where Docker Hub is reachable, :func:`ensure_bases` pulls them
and nothing else here runs.  Where it is not (the project's own machines reach only
the Python, Debian and npm package registries), it builds each of them locally,
under the same tag, from Debian bookworm packages:

* a root file system by ``debootstrap --variant=minbase bookworm`` (the mirror of
  this machine's own apt sources), imported with ``docker import`` as
  ``steelpath-standin/bookworm:minbase``;
* ``python:3.11-slim-bookworm``: Debian's ``python3.11`` with ``venv`` and ``pip``,
  ``ca-certificates``, ``netbase``, ``tzdata`` (what the official image adds to
  ``debian:bookworm-slim``; its Python is built from source instead, and it has
  no ``libgomp1`` either, so the product's image must install what its wheels
  need, as it must on the official one);
* ``postgres:15-bookworm``: Debian's ``postgresql-15`` behind an entrypoint that
  honours ``POSTGRES_USER``, ``POSTGRES_PASSWORD`` and ``POSTGRES_DB`` on an empty
  ``PGDATA`` (``/var/lib/postgresql/data``), listens on every address with
  password authentication, runs as ``postgres`` and stops on SIGINT, as the
  official one does;
* ``caddy:2``: Debian's ``caddy`` package (2.6), run as the official image runs it
  (``caddy run --config /etc/caddy/Caddyfile --adapter caddyfile``).

Where PyPI is reached only through this machine's certificate authority, the
stand-ins carry this machine's CA bundle (``/etc/ssl/certs/ca-certificates.crt``)
and point pip at it (``PIP_CERT``); their builds, and the product's, run with
``--network host``.  None of this is in the product's Dockerfile: on a machine with
Docker Hub, the same compose file pulls the official images unchanged.

Run by hand: ``python -m tests.support.docker_standins`` (starts no daemon; needs
one running, ``debootstrap`` and root); ``--clean`` untags the stand-ins again.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

BASE_TAG = "steelpath-standin/bookworm:minbase"
#: On every stand-in, so ``make docker-clean`` removes them and never a pulled image.
LABEL = "org.steelpath.standin=1"
HOST_CA = Path("/etc/ssl/certs/ca-certificates.crt")
DEFAULT_MIRROR = "http://deb.debian.org/debian"


class DockerUnavailable(RuntimeError):
    """The Docker daemon could not be reached or started; the message says why."""


def run(
    args: list[str], *, timeout: float = 600, check: bool = True, input: bytes | None = None
) -> subprocess.CompletedProcess[str]:
    """Run a command; on failure raise with its output, so a test says what went wrong."""
    r = subprocess.run(
        args,
        capture_output=True,
        timeout=timeout,
        input=input.decode() if input is not None else None,
        text=True,
    )
    if check and r.returncode != 0:
        raise RuntimeError(
            f"{' '.join(args)} exited {r.returncode}\n--- stdout\n{r.stdout[-4000:]}"
            f"\n--- stderr\n{r.stderr[-4000:]}"
        )
    return r


def docker_env() -> dict[str, str]:
    """The classic builder: BuildKit needs the buildx plugin, which Debian's docker.io lacks."""
    return {**os.environ, "DOCKER_BUILDKIT": "0", "COMPOSE_DOCKER_CLI_BUILD": "0"}


def daemon_up() -> bool:
    r = subprocess.run(["docker", "info"], capture_output=True, timeout=30)
    return r.returncode == 0


@dataclass
class Daemon:
    """The daemon the tests use; ``started`` when this process started it (and stops it)."""

    started: subprocess.Popen[bytes] | None
    log: Path | None

    def stop(self) -> None:
        if self.started is None:
            return
        self.started.terminate()
        try:
            self.started.wait(30)
        except subprocess.TimeoutExpired:
            self.started.kill()
            self.started.wait(10)


def start_daemon(log_dir: Path) -> Daemon:
    """Use the running daemon, or start ``dockerd`` (as root) and wait until it answers."""
    if shutil.which("docker") is None:
        raise DockerUnavailable("the docker client is not installed ('apt-get install docker.io')")
    if daemon_up():
        return Daemon(None, None)
    dockerd = shutil.which("dockerd")
    if dockerd is None:
        raise DockerUnavailable("dockerd is not installed ('apt-get install docker.io')")
    if os.geteuid() != 0:
        raise DockerUnavailable("no Docker daemon is running, and starting dockerd needs root")
    log = log_dir / "dockerd.log"
    with log.open("wb") as out:
        proc = subprocess.Popen([dockerd], stdout=out, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise DockerUnavailable(
                f"dockerd exited {proc.returncode} at start:\n{log.read_text()[-3000:]}"
            )
        if daemon_up():
            return Daemon(proc, log)
        time.sleep(0.5)
    proc.kill()
    raise DockerUnavailable(f"dockerd did not answer in 60 s:\n{log.read_text()[-3000:]}")


def image_exists(tag: str) -> bool:
    return run(["docker", "image", "inspect", tag], check=False, timeout=60).returncode == 0


def _apt_mirror() -> str:
    """The Debian mirror this machine's apt uses (deb822 or one-line sources)."""
    for path in [
        Path("/etc/apt/sources.list.d/debian.sources"),
        Path("/etc/apt/sources.list"),
    ]:
        if not path.is_file():
            continue
        for line in path.read_text().splitlines():
            line = line.strip()
            if line.startswith("URIs:"):
                return line.split()[1]
            if line.startswith("deb ") and "security" not in line:
                return next(w for w in line.split()[1:] if "://" in w)
    return DEFAULT_MIRROR


def _build(tag: str, dockerfile: str, files: dict[str, bytes]) -> None:
    with tempfile.TemporaryDirectory(prefix="steelpath-standin-") as d:
        ctx = Path(d)
        (ctx / "Dockerfile").write_text(dockerfile)
        for name, data in files.items():
            (ctx / name).write_bytes(data)
            (ctx / name).chmod(0o755 if name.endswith(".sh") else 0o644)
        r = subprocess.run(
            ["docker", "build", "--network", "host", "-t", tag, str(ctx)],
            capture_output=True,
            text=True,
            timeout=900,
            env=docker_env(),
        )
        if r.returncode != 0:
            raise RuntimeError(f"building the stand-in {tag} failed:\n{r.stdout[-4000:]}{r.stderr}")


def _base() -> None:
    """``steelpath-standin/bookworm:minbase`` from debootstrap, with apt set up like this machine."""
    if image_exists(BASE_TAG):
        return
    if shutil.which("debootstrap") is None:
        raise DockerUnavailable("debootstrap is not installed ('apt-get install debootstrap')")
    mirror = _apt_mirror()
    with tempfile.TemporaryDirectory(prefix="steelpath-rootfs-", dir="/var/tmp") as d:
        root = Path(d) / "root"
        run(
            ["debootstrap", "--variant=minbase", "bookworm", str(root), mirror],
            timeout=1200,
        )
        (root / "etc/apt/sources.list").write_text(
            f"deb {mirror} bookworm main\ndeb {mirror} bookworm-updates main\n"
            f"deb {mirror.replace('/debian', '/debian-security')} bookworm-security main\n"
        )
        # A snapshot mirror's Release files are old on purpose; apt must accept them.
        (root / "etc/apt/apt.conf.d/99standin").write_text(
            'Acquire::Check-Valid-Until "false";\nAcquire::Check-Date "false";\n'
            'APT::Install-Recommends "false";\n'
        )
        shutil.rmtree(root / "var/cache/apt/archives", ignore_errors=True)
        (root / "var/cache/apt/archives/partial").mkdir(parents=True, exist_ok=True)
        tar = subprocess.Popen(["tar", "-C", str(root), "-c", "."], stdout=subprocess.PIPE)
        imp = subprocess.run(
            ["docker", "import", "-c", 'CMD ["bash"]', "-c", f"LABEL {LABEL}", "-", BASE_TAG],
            stdin=tar.stdout,
            capture_output=True,
            text=True,
            timeout=600,
        )
        tar.wait(60)
        if imp.returncode != 0 or tar.returncode != 0:
            raise RuntimeError(f"docker import of the bookworm root failed: {imp.stderr}")


_CA = (
    "COPY host-ca.crt /etc/ssl/certs/ca-certificates.crt\n"
    "ENV PIP_CERT=/etc/ssl/certs/ca-certificates.crt "
    "SSL_CERT_FILE=/etc/ssl/certs/ca-certificates.crt "
    "REQUESTS_CA_BUNDLE=/etc/ssl/certs/ca-certificates.crt\n"
)

PYTHON_DOCKERFILE = f"""FROM {BASE_TAG}
LABEL {LABEL}
ENV LANG=C.UTF-8 DEBIAN_FRONTEND=noninteractive
RUN apt-get update -qq \\
 && apt-get install -y -qq python3.11 python3.11-venv python3-pip ca-certificates netbase tzdata \\
 && ln -s /usr/bin/python3 /usr/local/bin/python \\
 && rm -rf /var/lib/apt/lists/*
{_CA}CMD ["python3"]
"""

POSTGRES_ENTRYPOINT = """#!/bin/sh
# Stand-in for the official postgres image's entrypoint: an empty PGDATA is
# initialised with POSTGRES_USER / POSTGRES_PASSWORD / POSTGRES_DB, then the
# server runs as the postgres user in the foreground.
set -eu
: "${POSTGRES_USER:=postgres}"
: "${POSTGRES_DB:=$POSTGRES_USER}"
if [ -z "${POSTGRES_PASSWORD:-}" ]; then
  echo "Error: POSTGRES_PASSWORD is not set" >&2
  exit 1
fi
mkdir -p "$PGDATA" /var/run/postgresql
chown postgres:postgres "$PGDATA" /var/run/postgresql
chmod 700 "$PGDATA"
as_pg() { setpriv --reuid=postgres --regid=postgres --init-groups "$@"; }
if [ ! -s "$PGDATA/PG_VERSION" ]; then
  pw=$(mktemp); chown postgres "$pw"
  printf '%s\\n' "$POSTGRES_PASSWORD" > "$pw"
  as_pg initdb -D "$PGDATA" -U "$POSTGRES_USER" --pwfile="$pw" --auth-local=trust \\
    --auth-host=scram-sha-256 >/dev/null
  rm -f "$pw"
  echo "host all all all scram-sha-256" >> "$PGDATA/pg_hba.conf"
  if [ "$POSTGRES_DB" != "postgres" ]; then
    as_pg postgres -D "$PGDATA" -c listen_addresses='' >/dev/null 2>&1 &
    until as_pg pg_isready -q -U "$POSTGRES_USER" -d postgres; do sleep 0.2; done
    as_pg psql -q -U "$POSTGRES_USER" -d postgres -c "CREATE DATABASE \\"$POSTGRES_DB\\""
    as_pg pg_ctl -D "$PGDATA" -m fast -w stop >/dev/null
  fi
fi
if [ "${1:-postgres}" = "postgres" ]; then
  shift || true
  exec setpriv --reuid=postgres --regid=postgres --init-groups \\
    postgres -D "$PGDATA" -c listen_addresses='*' "$@"
fi
exec "$@"
"""

POSTGRES_DOCKERFILE = f"""FROM {BASE_TAG}
LABEL {LABEL}
ENV LANG=C.UTF-8 DEBIAN_FRONTEND=noninteractive
RUN apt-get update -qq \\
 && apt-get install -y -qq postgresql-15 \\
 && rm -rf /var/lib/apt/lists/*
ENV PATH=/usr/lib/postgresql/15/bin:$PATH PGDATA=/var/lib/postgresql/data
COPY docker-entrypoint.sh /usr/local/bin/docker-entrypoint.sh
VOLUME /var/lib/postgresql/data
EXPOSE 5432
STOPSIGNAL SIGINT
ENTRYPOINT ["/usr/local/bin/docker-entrypoint.sh"]
CMD ["postgres"]
"""

CADDY_DOCKERFILE = f"""FROM {BASE_TAG}
LABEL {LABEL}
# wget: the official (Alpine) image has busybox wget, which the compose health check uses
ENV DEBIAN_FRONTEND=noninteractive XDG_CONFIG_HOME=/config XDG_DATA_HOME=/data
RUN apt-get update -qq \\
 && apt-get install -y -qq caddy ca-certificates wget \\
 && rm -rf /var/lib/apt/lists/* \\
 && mkdir -p /config /data /etc/caddy
EXPOSE 80 443 2019
CMD ["caddy", "run", "--config", "/etc/caddy/Caddyfile", "--adapter", "caddyfile"]
"""


def _standin(tag: str) -> None:
    ca = HOST_CA.read_bytes() if HOST_CA.is_file() else b""
    if tag.startswith("python:"):
        _build(tag, PYTHON_DOCKERFILE, {"host-ca.crt": ca})
    elif tag.startswith("postgres:"):
        _build(tag, POSTGRES_DOCKERFILE, {"docker-entrypoint.sh": POSTGRES_ENTRYPOINT.encode()})
    elif tag.startswith("caddy:"):
        _build(tag, CADDY_DOCKERFILE, {})
    else:
        raise ValueError(f"no stand-in is known for {tag}")


BASE_IMAGES = ("python:3.11-slim-bookworm", "postgres:15-bookworm", "caddy:2")


def ensure_bases(tags: tuple[str, ...] = BASE_IMAGES) -> dict[str, str]:
    """Each tag present: already there, pulled, or built as a stand-in; says which."""
    how: dict[str, str] = {}
    for tag in tags:
        if image_exists(tag):
            how[tag] = "present"
            continue
        pulled = run(["docker", "pull", tag], check=False, timeout=600)
        if pulled.returncode == 0:
            how[tag] = "pulled"
            continue
        _base()
        _standin(tag)
        how[tag] = "stand-in"
    return how


@contextlib.contextmanager
def daemon(log_dir: Path) -> Iterator[Daemon]:
    d = start_daemon(log_dir)
    try:
        yield d
    finally:
        d.stop()


def remove_standins() -> list[str]:
    """Untag the stand-ins (their label tells them from pulled images); the tags removed."""
    removed = []
    for tag in (*BASE_IMAGES, BASE_TAG):
        labels = run(
            ["docker", "image", "inspect", "--format", "{{json .Config.Labels}}", tag],
            check=False,
            timeout=60,
        )
        key, _, value = LABEL.partition("=")
        if labels.returncode == 0 and f'"{key}":"{value}"' in labels.stdout.replace(" ", ""):
            run(["docker", "rmi", tag], timeout=120)
            removed.append(tag)
    return removed


if __name__ == "__main__":
    import sys

    if sys.argv[1:] == ["--clean"]:
        print("removed:", " ".join(remove_standins()) or "no stand-in")
    else:
        for tag, how in ensure_bases().items():
            print(f"{tag}: {how}")

"""A real Docker daemon, the compose file's base images and the product image, for the tests.

Session scope: the daemon is started when none runs (as root; stopped at the
end), the base images are pulled or built as stand-ins from Debian packages
(``tests/support/docker_standins.py`` says how and why), and the product image is
built from ``docker/Dockerfile`` under a tag of this run's own.  At the end the
tag is removed (``--no-prune``: its layers stay as the build cache, so the next
run rebuilds only what changed; ``make docker-clean`` removes the cache and the
stand-ins).  A daemon that cannot be started fails the tests with the reason.
"""

from __future__ import annotations

import os
import secrets
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass

import pytest

from tests.support.docker_compose import ROOT
from tests.support.docker_standins import (
    DockerUnavailable,
    docker_env,
    ensure_bases,
    run,
    start_daemon,
)


@dataclass(frozen=True)
class Image:
    """The product image this run built, and what it measured building it."""

    tag: str
    build_s: float
    size_bytes: int
    bases: dict[str, str]


@pytest.fixture(scope="session")
def docker_image(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Image]:
    try:
        daemon = start_daemon(tmp_path_factory.mktemp("dockerd"))
    except DockerUnavailable as e:
        pytest.fail(f"the Docker tests need a daemon: {e}")
    tag = f"steelpath-test:{os.getpid()}-{secrets.token_hex(3)}"
    try:
        bases = ensure_bases()
        t0 = time.monotonic()
        r = subprocess.run(
            ["docker", "build", "--network", "host", "-f", "docker/Dockerfile", "-t", tag, "."],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=1800,
            env=docker_env(),
        )
        build_s = time.monotonic() - t0
        assert r.returncode == 0, f"docker build failed:\n{r.stdout[-6000:]}\n{r.stderr[-3000:]}"
        size = int(run(["docker", "image", "inspect", "--format", "{{.Size}}", tag]).stdout)
        print(f"\nimage {tag}: built in {build_s:.1f} s, {size / 1e6:.0f} MB; bases {bases}")
        yield Image(tag, build_s, size, bases)
    finally:
        run(["docker", "rmi", "--no-prune", tag], check=False, timeout=120)
        daemon.stop()

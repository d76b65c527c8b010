"""``steelpath plan submit KIND FILE`` with a params file it cannot use: one
line naming the file and exit status 2, never a traceback (no server is
needed: the file is read before any request)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from tests.cli.test_cli import steelpath

# Nothing listens on port 9 (discard): a request made by mistake fails at once.
NO_SERVER = ["--server", "http://127.0.0.1:9", "--token", "sp_unused"]


def _one_line_error(r: subprocess.CompletedProcess[str], *needles: str) -> None:
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    for needle in needles:
        assert needle in lines[0], r.stderr


def test_a_missing_params_file_is_one_line_naming_it(tmp_path: Path) -> None:
    missing = tmp_path / "no-such-params.json"
    r = steelpath("plan", "submit", "demo.route", str(missing), *NO_SERVER)
    _one_line_error(r, str(missing), "No such file")


def test_a_directory_as_params_file_is_one_line(tmp_path: Path) -> None:
    r = steelpath("plan", "submit", "demo.route", str(tmp_path), *NO_SERVER)
    _one_line_error(r, str(tmp_path))


@pytest.mark.parametrize(
    ("name", "content", "needle"),
    [
        ("nan.json", b'{"max_length_m": NaN}', "NaN"),
        ("inf.json", b'{"nodes": {"a0": [0, 0, -Infinity]}}', "-Infinity"),
        ("latin1.json", b'{"start": "\xe9"}', "UTF-8"),
        ("broken.json", b"{nope", "not valid JSON"),
    ],
)
def test_a_params_file_that_is_not_strict_json_is_one_line(
    tmp_path: Path, name: str, content: bytes, needle: str
) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    r = steelpath("plan", "submit", "demo.route", str(path), *NO_SERVER)
    _one_line_error(r, str(path), needle)

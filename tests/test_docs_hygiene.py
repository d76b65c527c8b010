"""The documentation stays a reference: a short README, pages that say what is
true now without pointing at the work sessions or tickets that produced it,
and links that lead somewhere."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

README_MAX_LINES = 150

#: The folders and files that make up the product.
PRODUCT = [
    "server",
    "planners",
    "robots",
    "web_static",
    "tests",
    "docs",
    "docker",
    "scripts",
    "README.md",
    "Makefile",
    "pyproject.toml",
]
EXCLUDED = ("web_static/vendor/",)

# Built from pieces so that this file does not match its own pattern.
_HASH = "#"
_NUM = "[0-9]"
REFERENCE = re.compile(
    "|".join(
        [
            "session " + _NUM,
            "issue " + _HASH + _NUM,
            "issues? " + _HASH,
            r"\(" + _HASH + _NUM + r"+\)",
            "issue-" + _HASH,
        ]
    ),
    re.IGNORECASE,
)

LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
CODE = re.compile(r"```.*?```|`[^`\n]*`", re.DOTALL)  # code is not a link


def _tracked(paths: list[str]) -> list[str]:
    try:
        out = subprocess.run(
            ["git", "ls-files", "--", *paths],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the tracked files are unknown")
    return [p for p in out.splitlines() if not p.startswith(EXCLUDED)]


def test_readme_is_short() -> None:
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, (
        f"README.md has {len(lines)} lines (at most {README_MAX_LINES}): "
        "move detail into a page under docs/"
    )


def test_no_product_file_names_a_session_or_an_issue() -> None:
    hits = []
    for rel in _tracked(PRODUCT):
        path = ROOT / rel
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, FileNotFoundError, IsADirectoryError):
            continue  # binary (images, archives) or deleted in the work tree
        for n, line in enumerate(text.splitlines(), 1):
            if REFERENCE.search(line):
                hits.append(f"{rel}:{n}: {line.strip()[:120]}")
    assert not hits, "say what is true without the session or issue it came from:\n" + "\n".join(
        hits
    )


def _doc_pages() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


@pytest.mark.parametrize("page", _doc_pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_point_at_files(page: Path) -> None:
    broken = []
    for target in LINK.findall(CODE.sub("", page.read_text(encoding="utf-8"))):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#"):
            continue  # a URL (http:, mailto:) or an anchor on the same page
        path = target.split("#", 1)[0]
        if not (page.parent / path).exists():
            broken.append(target)
    assert not broken, f"{page.relative_to(ROOT)} links to missing files: {broken}"

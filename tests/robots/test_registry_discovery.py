"""A robot is its description folder: ``robots/<name>/<name>.urdf`` (no list to edit)."""

from __future__ import annotations

from pathlib import Path

from robots import ROBOT_NAMES
from robots.registry import _discover


def test_the_four_built_in_robots_are_discovered() -> None:
    assert ROBOT_NAMES == ("ara", "cmbot", "denso_vm6083", "sbg_climber")


def test_only_folders_with_their_urdf_and_a_package_count(tmp_path: Path) -> None:
    def folder(name: str, urdf: str | None, init: bool = True) -> None:
        d = tmp_path / name
        d.mkdir()
        if init:
            (d / "__init__.py").write_text("")
        if urdf is not None:
            (d / urdf).write_text("<robot/>")

    folder("zeta_arm", "zeta_arm.urdf")
    folder("alpha", "alpha.urdf")
    folder("protocol", None)  # code, not a robot
    folder("misnamed", "other.urdf")  # the URDF must carry the folder's name
    folder("loose", "loose.urdf", init=False)  # not importable: not a robot
    (tmp_path / "stray.urdf").write_text("<robot/>")
    assert _discover(tmp_path) == ("alpha", "zeta_arm")

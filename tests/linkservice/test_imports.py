"""The robot-link service is the E-stop path: it starts (and restarts after a
crash) on what the protocol and the adapters need, not on the mesh and URDF
libraries the planners and the scene use."""

from __future__ import annotations

from tests.support.imports import loaded_by

#: Libraries the service never needs: mesh handling and URDF parsing (1 s of
#: the 1.5 s it took to import before), plotting, OMPL, the 3D scene and the
#: planners.  (pinocchio, 0.08 s, comes with ``robots.model`` and brings coal.)
HEAVY = ("trimesh", "yourdfpy", "matplotlib", "ompl", "viser", "planners")


def test_the_link_service_starts_without_the_heavy_libraries() -> None:
    loaded = loaded_by("server.linkservice.service", HEAVY)
    assert loaded == [], f"the link service imports {' '.join(loaded)}"


def test_the_robot_models_still_parse_their_urdf() -> None:
    from robots.registry import load_robot
    from robots.urdf_model import urdf_description

    ara = load_robot("ara")
    assert urdf_description(ara.urdf_path).joint_map, "no joints parsed"

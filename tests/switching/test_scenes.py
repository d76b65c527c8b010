"""Every test scene gives the verdict of the seed's experiment (§5.2.1)."""

from __future__ import annotations

import numpy as np
import pytest

import robots
from planners.switching import decide_mode
from planners.switching.scenes import SCENES, DepthCamera, make_scene

FOOT = (0.18, 0.12)

#: The mode each scene must give, from the seed document
#: (shared/seeds/000_7892b1b5c9cefad2.txt): Eq. 3.1 S = Spa·Sam·Shc — "The
#: robot configures into mobile transformation if the function S returns a
#: true value. The false value configures the robot into the inch-worm
#: transformation"; with no plane (Eq. 3.2, Spa = False) or no area for a foot
#: (Sam = False, Fig. 5.2) there is nothing to move onto: "none".
EXPECTED_MODE: dict[str, str] = {
    # Fig. 5.3(a): height equal to the base height → Shc = True → mobile
    "same_height": "mobile",
    # Fig. 5.3(b): "d = 7cm lower than the robot base ... Shc was false, and
    # robot performs inch-worm transformation"
    "step_down_7cm": "inchworm",
    # Fig. 5.4: the jump onto a perpendicular slab is the inch-worm transformation
    "perpendicular": "inchworm",
    # Fig. 5.2(b)-(c): "Only the green rectangle was inside ... there is enough
    # area for an inch-worm jump, the variable Sam is set to true" (a plate below the base)
    "narrow_surface": "inchworm",
    # Fig. 5.2: rectangles "not sufficient enough for an inch-worm jump" → Sam = False
    "too_small": "none",
    # §5.1: corroded slabs at base height still give Spa, Sam, Shc = True → mobile
    "corroded_slab": "mobile",
    # Eq. 3.2: "Spa = False, if Pcl = ∅"
    "no_surface": "none",
}


def test_every_scene_has_a_seed_verdict():
    assert set(EXPECTED_MODE) == set(SCENES)


def _decide(name: str, seed: int):
    sc = make_scene(name, seed)
    return sc, decide_mode(sc.points, camera_to_base=sc.camera_to_base, base_height=0.0, foot=FOOT)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("name", list(SCENES))
def test_scene_verdict(name, seed):
    _, d = _decide(name, seed)
    assert d.mode == EXPECTED_MODE[name], d.message
    # The summary is JSON-able numbers and strings.
    assert all(isinstance(v, (int, float, str, bool, type(None))) for v in d.summary().values())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_height_values(seed):
    _, same = _decide("same_height", seed)
    assert same.height_available and abs(same.height_error_m) <= 0.005
    _, down = _decide("step_down_7cm", seed)
    assert not down.height_available
    assert down.height_error_m == pytest.approx(-0.07, abs=0.003)  # Fig. 5.3(b): 7 cm lower
    assert down.foothold is not None
    # The foothold lies on the lower slab, facing up, within reach.
    np.testing.assert_allclose(down.foothold[2, 3], -0.07, atol=0.005)
    assert down.foothold[2, 2] > 0.99
    assert np.linalg.norm(down.foothold[:3, 3]) <= 0.5


def test_perpendicular_slab_is_the_target():
    _, d = _decide("perpendicular", 0)
    wall = d.chosen
    assert wall.normal_angle_deg == pytest.approx(90.0, abs=2.0)
    np.testing.assert_allclose(wall.normal, [-1, 0, 0], atol=0.03)  # faces the robot
    assert d.foothold is not None and d.foothold[0, 3] == pytest.approx(0.45, abs=0.01)


@pytest.mark.parametrize("seed", range(5))
def test_narrow_surface_one_of_five(seed):
    """Fig. 5.2(b)-(c): of five rectangles only one fits."""
    _, d = _decide("narrow_surface", seed)
    assert d.rectangles_total == 5
    assert d.rectangles_passed == 1
    assert d.area_available


def test_too_small_and_no_surface():
    _, small = _decide("too_small", 0)
    assert small.plane_available and not small.area_available
    assert small.rectangles_passed == 0
    _, none = _decide("no_surface", 0)
    assert not none.plane_available and none.candidates == []


def test_corroded_slab_planes_and_holes():
    sc, d = _decide("corroded_slab", 0)
    assert d.mode == "mobile"
    # The pits are real gaps in the scan: fewer points than the intact slab.
    intact = make_scene("same_height", 0)
    assert len(sc.points) < len(intact.points)


def test_scenes_are_deterministic_and_noisy():
    a, b = make_scene("step_down_7cm", 3), make_scene("step_down_7cm", 3)
    np.testing.assert_array_equal(a.points, b.points)
    c = make_scene("step_down_7cm", 4)
    assert not np.array_equal(a.points, c.points)
    # Depth noise: lower-slab points scatter around z = -0.07 by mm, not 0.
    z = a.points_base()[:, 2]
    lower = z[np.abs(z + 0.07) < 0.02]
    assert 0.0005 < lower.std() < 0.005


def test_camera_model_matches_robot_description():
    ara = robots.load_robot("ara")
    cam = ara.params["camera"]
    d = DepthCamera()
    assert list(d.position) == cam["xyz_m"]
    assert d.pitch_down_deg == cam["pitch_down_deg"]
    assert (d.hfov_deg, d.vfov_deg) == (cam["hfov_deg"], cam["vfov_deg"])
    np.testing.assert_allclose(d.camera_to_base(), ara.camera_to_base, atol=1e-12)

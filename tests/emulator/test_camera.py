"""The emulator's camera (robots/emulator/camera.py) and captures end to end: the points
land where the geometry says (within the noise model), a point behind another one is
occluded, the world file is bounded and reloaded, and the host gets each capture —
complete, before the report that completes its command — through the link."""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from robots.adapters import ExecState, RobotLink, Streamer
from robots.emulator import Emulator, SimRobot, resolve_profile
from robots.emulator import camera as camera_mod
from robots.emulator.camera import CameraSpec, Cloud, World, WorldError, load_world, render
from robots.emulator.cli import main
from robots.protocol import BasePose, Capture, Program, SensorCapture, Stop, WheelSpeeds
from robots.protocol.capture import rpy_to_matrix
from robots.protocol.messages import CaptureHeader, Feature, Hello

from .helpers import link_config

ARA = resolve_profile("ara")
CAM = ARA.camera
assert CAM is not None


def sigma(z: np.ndarray, spec: CameraSpec = CAM) -> np.ndarray:
    return spec.noise_sigma0_m + spec.noise_sigma2_per_m * (z - 0.4) ** 2


def ground(spacing: float = 0.005, size: float = 3.0) -> np.ndarray:
    """The standing surface z = 0 of the base frame, ahead of the robot."""
    g = np.arange(0.0, size, spacing)
    x, y = np.meshgrid(g, g - size / 2)
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)]).astype(np.float32)


def facing_plane(T_wc: np.ndarray, depth: float, half: float = 3.0, spacing: float = 0.004):
    """A plane perpendicular to the view axis at ``depth`` m, in world coordinates."""
    g = np.arange(-half, half, spacing)
    x, y = np.meshgrid(g, g)
    cam = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, depth)])
    return (cam @ T_wc[:3, :3].T + T_wc[:3, 3]).astype(np.float32)


def to_camera(points_w: np.ndarray, T_wc: np.ndarray) -> np.ndarray:
    return (np.asarray(points_w, float) - T_wc[:3, 3]) @ T_wc[:3, :3]


def test_ground_points_land_on_the_ground_within_the_noise() -> None:
    T_wc = CAM.camera_to_base  # base at the world origin
    pts, inten = render(CAM, ground(), None, T_wc, np.random.default_rng(0))
    assert inten is None and 1000 < len(pts) <= CAM.max_points
    z = pts[:, 2].astype(float)
    assert z.min() >= CAM.min_range_m - 0.05 and z.max() <= CAM.max_range_m + 0.05
    # In the frustum.
    assert np.all(np.abs(pts[:, 0] / z) <= math.tan(CAM.hfov_rad / 2) + 1e-6)
    assert np.all(np.abs(pts[:, 1] / z) <= math.tan(CAM.vfov_rad / 2) + 1e-6)
    world = pts.astype(float) @ T_wc[:3, :3].T + T_wc[:3, 3]
    # Axial noise moves a point along its ray: the height error is the range error
    # times the ray's vertical component; 5 σ covers every point of 2 048.
    ray = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    vertical = np.abs(ray @ T_wc[:3, :3].T[:, 2]) * np.linalg.norm(pts, axis=1) / z
    assert np.all(np.abs(world[:, 2]) <= 5 * sigma(z) * vertical + 1e-4)
    assert world[:, 0].min() > 0.25  # the ground is seen from ~0.32 m ahead


def test_without_noise_every_point_is_a_world_point() -> None:
    from scipy.spatial import cKDTree

    exact = dataclasses.replace(CAM, noise_sigma0_m=0.0, noise_sigma2_per_m=0.0)
    T_wc = np.eye(4)
    T_wc[:3, :3] = rpy_to_matrix((0.3, -0.2, 1.0))
    T_wc[:3, 3] = (5.0, -7.0, 2.0)
    world = facing_plane(T_wc, 1.3, half=1.2, spacing=0.01)
    pts, _ = render(exact, world, None, T_wc, np.random.default_rng(0))
    assert len(pts) > 500 and np.all(np.abs(pts[:, 2] - 1.3) < 1e-4)
    back = pts.astype(float) @ T_wc[:3, :3].T + T_wc[:3, 3]
    # Each returned point is one of the world's, up to float32 rounding of
    # coordinates near (5, −7, 2); the world's spacing is 10 mm.
    dist, _ = cKDTree(world.astype(float)).query(back)
    assert dist.max() < 1e-5


def test_a_point_behind_another_one_is_occluded() -> None:
    exact = dataclasses.replace(CAM, noise_sigma0_m=0.0, noise_sigma2_per_m=0.0)
    T_wc = exact.camera_to_base
    # The ray through the centre of pixel (100, 40), in the camera frame.
    u = ((100 + 0.5) / exact.width_px * 2 - 1) * math.tan(exact.hfov_rad / 2)
    v = ((40 + 0.5) / exact.height_px * 2 - 1) * math.tan(exact.vfov_rad / 2)
    ray = np.array([u, v, 1.0])
    front = T_wc[:3, :3] @ (1.0 * ray) + T_wc[:3, 3]
    behind = T_wc[:3, :3] @ (1.8 * ray) + T_wc[:3, 3]  # the same ray, farther
    aside = T_wc[:3, :3] @ np.array([0.3, 0.0, 1.5]) + T_wc[:3, 3]
    world = np.array([behind, front, aside], dtype=np.float32)
    pts, _ = render(exact, world, None, T_wc, np.random.default_rng(0))
    got = sorted(np.round(pts[:, 2].astype(float), 3).tolist())
    assert got == [1.0, 1.5], got  # 1.8 m hides behind 1.0 m; the point aside is seen
    # Two walls filling the view: only the near one is seen.
    near = facing_plane(T_wc, 1.0, half=1.0, spacing=0.004)
    far = facing_plane(T_wc, 2.0, half=2.0, spacing=0.004)
    pts, _ = render(exact, np.vstack([far, near]), None, T_wc, np.random.default_rng(0))
    assert len(pts) == exact.max_points and np.all(np.abs(pts[:, 2] - 1.0) < 1e-4)


def test_the_grid_index_misses_nothing() -> None:
    """Against a brute-force reference: every world point, no index, a dict per pixel."""
    exact = dataclasses.replace(CAM, noise_sigma0_m=0.0, noise_sigma2_per_m=0.0)
    rng = np.random.default_rng(5)
    T_wc = np.eye(4)
    T_wc[:3, :3] = rpy_to_matrix((0.2, 0.3, -2.0))
    T_wc[:3, 3] = (-3.5, 7.2, 0.4)  # near cell corners, negative coordinates
    world = (T_wc[:3, 3] + rng.uniform(-3, 3, (20000, 3))).astype(np.float32)
    pts, _ = render(exact, world, None, T_wc, rng)
    cam = to_camera(world.astype(np.float32).astype(float), T_wc)
    th, tv = math.tan(exact.hfov_rad / 2), math.tan(exact.vfov_rad / 2)
    best: dict[tuple[int, int], float] = {}
    for x, y, z in cam:
        if not (exact.min_range_m <= z <= exact.max_range_m):
            continue
        if abs(x) > th * z or abs(y) > tv * z:
            continue
        u = min(int((x / z / th + 1) * 0.5 * exact.width_px), exact.width_px - 1)
        v = min(int((y / z / tv + 1) * 0.5 * exact.height_px), exact.height_px - 1)
        best[(u, v)] = min(best.get((u, v), np.inf), z)
    assert 100 < len(best) < exact.max_points
    assert len(pts) == len(best)
    assert np.allclose(np.sort(pts[:, 2]), np.sort(list(best.values())), atol=1e-5)


def test_range_noise_follows_the_model_and_the_seed() -> None:
    T_wc = CAM.camera_to_base
    world = facing_plane(T_wc, 2.0, half=1.5, spacing=0.003)
    a, _ = render(CAM, world, None, T_wc, np.random.default_rng([0, 1]))
    b, _ = render(CAM, world, None, T_wc, np.random.default_rng([0, 1]))
    c, _ = render(CAM, world, None, T_wc, np.random.default_rng([0, 2]))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    err = a[:, 2].astype(float) - 2.0
    want = float(sigma(np.array(2.0)))
    assert abs(err.mean()) < 0.2 * want and 0.85 * want < err.std() < 1.15 * want


def test_intensity_comes_with_the_points_it_belongs_to() -> None:
    exact = dataclasses.replace(CAM, noise_sigma0_m=0.0, noise_sigma2_per_m=0.0)
    T_wc = exact.camera_to_base
    world = facing_plane(T_wc, 1.0, half=0.6, spacing=0.02)
    inten = (np.arange(len(world)) % 251).astype(np.uint8)
    pts, got = render(exact, world, inten, T_wc, np.random.default_rng(0))
    from scipy.spatial import cKDTree

    back = pts.astype(float) @ T_wc[:3, :3].T + T_wc[:3, 3]
    _, nearest = cKDTree(world.astype(float)).query(back)
    assert got is not None and np.array_equal(got, inten[nearest])


def test_one_million_world_points_per_capture_is_fast(capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(1)
    n = 1_000_000
    worlds = {
        # A 40 m × 40 m deck with clutter: most of it out of view.
        "spread over 40 m x 40 m": np.column_stack(
            [rng.uniform(-20, 20, n), rng.uniform(-20, 20, n), rng.uniform(-0.05, 1.0, n)]
        ),
        # The worst case: every point in the frustum's bounding box.
        "all within 2.5 m ahead": np.column_stack(
            [rng.uniform(0.3, 2.5, n), rng.uniform(-1, 1, n), rng.uniform(-0.05, 0.5, n)]
        ),
    }
    T_wc = CAM.camera_to_base
    report = []
    for name, points in worlds.items():
        t0 = time.perf_counter()
        cloud = Cloud.build(points.astype(np.float32))  # once per (re)load of the file
        build_ms = (time.perf_counter() - t0) * 1000
        times = []
        for k in range(5):
            t0 = time.perf_counter()
            pts, _ = render(CAM, cloud, None, T_wc, np.random.default_rng(k))
            times.append((time.perf_counter() - t0) * 1000)
        assert len(pts) > 0
        report.append(f"{name}: {np.median(times):.1f} ms/capture (index {build_ms:.0f} ms)")
        # ~20 ms at worst unloaded; generous for a loaded CI machine.
        assert np.median(times) < 1000
    with capsys.disabled():
        print("\n1 M world points: " + "; ".join(report))


# --- the world file -------------------------------------------------------------------------


def write_world(path: Path, points: np.ndarray, intensity: np.ndarray | None = None) -> None:
    arrays = {"points": np.asarray(points, dtype=np.float32)}
    if intensity is not None:
        arrays["intensity"] = intensity
    tmp = path.with_name(path.stem + ".tmp.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def test_world_file_rules(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "world.npz"
    write_world(path, np.zeros((4, 3)))
    pts, inten = load_world(path)
    assert pts.dtype == np.float32 and pts.shape == (4, 3) and inten is None
    np.savez(path, points=np.zeros((4, 2), np.float32))
    with pytest.raises(WorldError, match=r"shape \(4, 2\)"):
        load_world(path)
    np.savez(path, cloud=np.zeros((4, 3), np.float32))
    with pytest.raises(WorldError, match="no 'points'"):
        load_world(path)
    np.savez(path, points=np.array([[0, 0, np.nan]], np.float32))
    with pytest.raises(WorldError, match="finite"):
        load_world(path)
    np.savez(path, points=np.array([[0, 0, 2500.0]], np.float32))
    with pytest.raises(WorldError, match="2000"):
        load_world(path)
    np.savez(path, points=np.zeros((4, 3), np.float32), intensity=np.zeros(3, np.uint8))
    with pytest.raises(WorldError, match="intensity of shape"):
        load_world(path)
    path.write_bytes(b"not a zip")
    with pytest.raises(WorldError, match="cannot read"):
        load_world(path)
    monkeypatch.setattr(camera_mod, "MAX_WORLD_POINTS", 10)
    write_world(path, np.zeros((11, 3)))
    with pytest.raises(WorldError, match="11 points > 10 allowed"):
        load_world(path)


def test_world_is_reloaded_when_the_file_changes(tmp_path: Path) -> None:
    path = tmp_path / "world.npz"
    world = World(path)
    assert world.current()[1].endswith("does not exist")
    write_world(path, np.zeros((3, 3)))
    assert len(world.current()[0]) == 3 and world.loads == 1
    assert len(world.current()[0]) == 3 and world.loads == 1  # unchanged: not read again
    write_world(path, np.ones((5, 3)), np.arange(5, dtype=np.uint8))
    os.utime(path, ns=(time.time_ns(), time.time_ns() + 10**9))  # a coarse clock
    cloud, _ = world.current()
    assert cloud is not None and len(cloud) == 5 and cloud.intensity is not None
    assert world.loads == 2
    path.write_bytes(b"broken")
    cloud, why = world.current()
    assert cloud is None and "cannot read" in why


def test_emulator_refuses_a_broken_world_at_start(tmp_path: Path, capsys) -> None:
    path = tmp_path / "world.npz"
    np.savez(path, points=np.zeros((2, 4), np.float32))
    with pytest.raises(WorldError):
        Emulator("ara", world=path)
    assert main(["--robot", "ara", "--world", str(path)]) == 2
    assert "expected (N, 3)" in capsys.readouterr().err


# --- captures end to end ----------------------------------------------------------------------


def test_sim_robot_capture_without_a_world_is_empty_and_says_why(caplog) -> None:
    robot = SimRobot(ARA, clock=lambda: 0.0)
    (ack, _) = robot.receive(Hello(watchdog_ms=2000), 0, now=0.0)
    assert ack.features & Feature.CAMERA
    with caplog.at_level(logging.WARNING, logger="robots.emulator.robot"):
        robot.receive(Capture().to_message(3, 0), 1, now=0.0)
        robot.advance(0.01)
    (header,) = robot.take_outbox()
    assert isinstance(header, CaptureHeader) and header.n_points == 0
    assert (header.capture_id, header.run_id, header.index) == (1, 3, 0)
    assert "no world loaded" in caplog.text
    # A robot without a camera refuses the command.
    generic = SimRobot(resolve_profile("generic"), clock=lambda: 0.0)
    generic.receive(Hello(watchdog_ms=2000), 0, now=0.0)
    (nak,) = generic.receive(Capture().to_message(3, 0), 1, now=0.0)
    assert nak.reason == 4  # INVALID


def test_captures_reach_the_host_in_order_and_where_the_geometry_says(tmp_path: Path) -> None:
    path = tmp_path / "world.npz"
    anchor = ((10.0, 5.0, 0.0), (0.0, 0.0, math.pi / 2))  # facing +y of the world
    T_wb = np.eye(4)
    T_wb[:3, :3] = rpy_to_matrix(anchor[1])
    T_wb[:3, 3] = anchor[0]
    g = ground()
    world = (g.astype(float) @ T_wb[:3, :3].T + T_wb[:3, 3]).astype(np.float32)
    write_world(path, world, (np.arange(len(world)) % 256).astype(np.uint8))
    program = Program(
        (
            BasePose(*anchor),
            Capture(),
            WheelSpeeds((0.1, 0.1), 1.0),  # 0.1 m along the base's x: +y in the world
            Capture(),
            Stop(),
            Capture(),  # the world is rewritten before this one: a wall ahead
        ),
        robot="ara",
    )
    events: list[tuple[str, int]] = []
    captures: list[SensorCapture] = []
    via_link: list[SensorCapture] = []
    rewrote = threading.Event()

    def on_ack(index: int) -> None:
        events.append(("ack", index))
        if index == 3:
            # 0.9 m ahead of where the camera is now (the second capture's pose).
            T_now = np.eye(4)
            T_now[:3, :3] = captures[-1].camera_rotation
            T_now[:3, 3] = captures[-1].camera_position_m
            wall = facing_plane(T_now, 0.9, half=1.0, spacing=0.01)
            write_world(path, wall)
            os.utime(path, ns=(time.time_ns(), time.time_ns() + 10**9))
            rewrote.set()

    def on_capture(cap: SensorCapture) -> None:
        events.append(("capture", cap.command_index))
        captures.append(cap)

    with (
        Emulator("ara", world=path, time_scale=4) as emu,
        RobotLink(emu.url, link_config(emu)) as link,
    ):
        unsubscribe = link.subscribe_captures(via_link.append)
        streamer = Streamer(
            program, link, run_id=77, on_ack=on_ack, on_capture=on_capture, window=1
        )
        with streamer:
            assert streamer.wait(timeout=30) == ExecState.COMPLETED
        unsubscribe()
        infos = emu.capture_log()
    assert rewrote.is_set()
    assert [c.capture_id for c in captures] == [1, 2, 3] == [c.capture_id for c in via_link]
    assert all(c.complete and c.run_id == 77 for c in captures)
    # Each capture comes before the acknowledgement of its command.
    for index in (1, 3, 5):
        assert events.index(("capture", index)) < events.index(("ack", index)), events
    first, second, third = captures
    T0 = T_wb @ CAM.camera_to_base
    assert np.allclose(first.camera_position_m, T0[:3, 3], atol=2e-6)
    assert np.allclose(first.camera_rotation, T0[:3, :3], atol=1e-6)
    assert np.allclose(second.camera_position_m - first.camera_position_m, [0, 0.1, 0], atol=1e-5)
    for cap in (first, second):
        assert len(cap.points_m) == len(cap.intensity) > 1000
        w = cap.world_points()
        z = cap.points_m[:, 2].astype(float)
        assert np.all(np.abs(w[:, 2]) <= 5 * sigma(z) + 2e-3)  # on the ground
    # The rewritten world: a wall 0.9 m ahead of the camera.
    assert len(third.points_m) > 1000 and third.intensity is None
    assert np.all(np.abs(third.points_m[:, 2] - 0.9) < 5 * sigma(np.array(0.9)) + 1e-3)
    assert [i.n_points for i in infos] == [len(c.points_m) for c in captures]
    assert all(i.reason == "" for i in infos)
